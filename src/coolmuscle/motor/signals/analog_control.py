"""Analog control: the loop that samples the analog input and drives the motor with it.

cml-users-guide.txt ch. 3 K38 (control type 0-10), K39 (low-pass filter), K40 (maximum
speed), K41 (travel range), K43/K44 (acceleration), and 5.5 / K74-K77 (torque
feedback).  The input is read through the 10-bit converter of :mod:`.analog`; 0-0.2 V
and 4.8-5 V are dead zones, and for the CW/CCW types 2.4-2.6 V is the zero band.

The loop runs only while a control type is active and the signal or the loop can
still change: the filter samples 5000 times a second (K39's unit, "5[rad/sec] =
5000[times/sec]/1024", is a first-order filter y += K39/1024 (x - y) per sample)
and the command is updated every millisecond.  When the filtered value has
settled on a steady input, the loop sleeps until the source changes again
(:meth:`AnalogSource.next_change`) or the input is set.  Choices:
docs/fidelity.md "Analog".
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from ...errors import MotorError
from ...sim.kernel import PRIO_MOTION, Timer
from ..motion.planner import Limits
from ..motion.profile import Profile, Segment
from ..state import units
from .analog import AnalogInput, counts_to_volts, volts_to_counts

if TYPE_CHECKING:
    from ..core import MotorCore

log = logging.getLogger(__name__)

SAMPLE_NS: Final = 200_000          # filter sample period: 5000 samples/s (K39 unit)
TICK_NS: Final = 1_000_000          # command update period
SAMPLES_PER_TICK: Final = TICK_NS // SAMPLE_NS
SETTLED: Final = 0.01               # counts: the filter has reached a steady input

# K38 dead zones, and the CW/CCW zero band
LO: Final = volts_to_counts(0.2)
HI: Final = volts_to_counts(4.8)
MID_LO: Final = volts_to_counts(2.4)
MID_HI: Final = volts_to_counts(2.6)

NONE: Final = 0
POSITION: Final = 1
SPEED_CW: Final = 2
SPEED_CCW: Final = 3
SPEED_BOTH: Final = 4
P_DATA: Final = 5
S_PLUS: Final = 6
S_MINUS: Final = 7
S_BOTH: Final = 8
TORQUE: Final = 9
TORQUE_FEEDBACK: Final = 10
SPEED_MODES: Final = (SPEED_CW, SPEED_CCW, SPEED_BOTH)

#: CM1 (cm1-ethernetip-interface-manual.txt Appendix A): K64 selects the analog
#: function; 9 = "Analog control only (K38)" with K38 0 speed / 1 position.
_CM1_K64: Final = {1: S_PLUS, 2: P_DATA}


def unipolar(y: float) -> float:
    """0..1 over 0.2..4.8 V (types 1, 2, 3, 5, 6, 7)."""
    return min(1.0, max(0.0, (y - LO) / (HI - LO)))


def bipolar(y: float) -> float:
    """-1..1: 2.6..4.8 V positive, 2.4..0.2 V negative, dead band between (4, 8, 9)."""
    if y > MID_HI:
        return min(1.0, (y - MID_HI) / (HI - MID_HI))
    if y < MID_LO:
        return -min(1.0, (MID_LO - y) / (MID_LO - LO))
    return 0.0


def effective_mode(motor: MotorCore) -> int:
    """The CM2 control type the parameters select (CM1 maps K64/K38 onto it)."""
    if motor.firmware.name == "cm1":
        k64 = motor.k(64)
        if k64 == 9:
            return POSITION if motor.k(38) == 1 else SPEED_CW
        return _CM1_K64.get(k64, NONE)
    return motor.k(38)


def friction_nm(plant: object, speed_pps: float, ppr: int) -> float:
    """Friction torque (N·m) opposing ``speed_pps``: Coulomb, plus viscous and a
    constant load torque where the load model has them."""
    if speed_pps == 0.0:
        return 0.0
    omega = speed_pps * 2 * math.pi / ppr
    coulomb = math.copysign(getattr(plant, "coulomb_friction", 0.0), speed_pps)
    return coulomb + getattr(plant, "viscous_friction", 0.0) * omega


def k40_pps(motor: MotorCore) -> float:
    """K40 (min⁻¹) in pulses/s of the current resolution."""
    return units.rpm_to_pps(motor.k(40), motor.k(37))


def k40_s_value(motor: MotorCore, fraction: float) -> int:
    """S = speed[min⁻¹] x resolution[ppr] / speed unit / 60, truncated (ch. 3 K40)."""
    res = motor.resolution
    return int(motor.k(40) * fraction * res.pulses_per_rev / res.speed_unit_pps / 60)


@dataclass
class _Feedback:
    """A torque feedback positioning in progress (5.5)."""

    target: float
    speed: float
    direction: int
    limits: Limits
    integral: float = 0.0


class AnalogControl:
    """K38 analog control of one motor."""

    def __init__(self, motor: MotorCore, analog_input: AnalogInput) -> None:
        self.motor = motor
        self.input = analog_input
        self.kernel = motor.kernel
        self.mode = NONE
        self.filtered = float(analog_input.counts())
        self.armed = False
        self.base = (0.0, 0.0)            # (target, fraction) position control starts from
        self.feedback: _Feedback | None = None
        self._own: Profile | None = None  # the trajectory this control installed
        self._data: int | None = None     # last P0/S0 written (types 5-8)
        self._speed: float | None = None  # last commanded speed, pps (types 2-4)
        self._torque: float | None = None  # torque it commands, % (type 9)
        self._waiting = False
        self._timer: Timer | None = None
        self._sleeping = True
        self._in_tick = False
        self.ticks = 0                    # loop samples so far (tests, benchmarks)
        self._driven_speed: float | None = None   # the torque feedback's last command
        analog_input.listeners.append(self.wake)
        motor.timeline.listeners.append(self._trajectory_changed)
        motor.params.on_change(self._param_changed)

    # -- activation and the loop ---------------------------------------------------
    def activate(self) -> None:
        """Power-up or a new control type: start from the current position and input."""
        if self._owns() and self.motor.axis.moving:
            self.motor.axis.stop(self._limits().decel)
        self.mode = effective_mode(self.motor)
        self.filtered = float(self.input.counts())
        self.armed = self._zero_speed_input()
        self.feedback = None
        self._own = self._data = self._speed = self._torque = None
        self._rebase()
        self._cancel()
        if self.mode == POSITION:
            self._next(self.kernel.now)   # starts where it is: nothing to do until it changes
        elif self.mode != NONE:
            self.wake()                   # apply the input once, steady or not

    def _param_changed(self, k: int, old: int, new: int) -> None:
        del old, new
        if k == 38 or (k == 64 and self.motor.firmware.name == "cm1"):
            self.activate()
        elif k == 41:
            self._rebase()
        elif k in (39, 40, 37):
            self.wake()

    def _dormant(self) -> bool:
        """No control type, or torque feedback with no positioning running (5.5)."""
        return self.mode == NONE or (self.mode == TORQUE_FEEDBACK and self.feedback is None)

    def wake(self) -> None:
        """The input or a setting changed: sample from the next millisecond on."""
        if self._dormant() or (self._timer is not None and not self._sleeping):
            return
        self._cancel()
        self._schedule(self.kernel.now + TICK_NS, sleeping=False)

    def _trajectory_changed(self, old: object, new: object) -> None:
        """Another motion started (or ended a wait): speed and torque control look again
        (a timeline listener: called at every motion, so with its two arguments named,
        not gathered)."""
        del old, new
        if not self._in_tick and (self.mode in SPEED_MODES or self.mode == TORQUE) \
                and not self._owns():
            self.wake()

    def _schedule(self, at: int, *, sleeping: bool) -> None:
        if self._timer is not None:
            self._timer.cancel()
        self._sleeping = sleeping
        self._timer = self.kernel.schedule_at(at, self._tick, priority=PRIO_MOTION,
                                              name="analog")

    def _cancel(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
        self._timer = None
        self._sleeping = True

    def _tick(self) -> None:
        self._timer = None
        self.ticks += 1
        now = self.kernel.now
        if not self._owns():
            self._rebase()
        self._filter(now)
        self._in_tick = True
        try:
            self._apply()
        except MotorError:
            pass                        # a value the motor refuses is not applied
        except ValueError as exc:       # no plan for these settings: skip this sample
            log.warning("motor %d: analog control: %s", self.motor.id, exc)
        finally:
            self._in_tick = False
        self._next(now)

    def _next(self, now: int) -> None:
        """Tick again in 1 ms while busy; else sleep until the source changes."""
        if self._dormant():
            self._cancel()
            return
        if self._waiting and self._settled(now):
            end = self.motor.axis.profile.end_ns    # wait for the other motion to end
            if end is None:
                self._cancel()                      # endless: its next change wakes us
            else:
                self._schedule(max(end, now + TICK_NS), sleeping=False)
            return
        if self._busy(now):
            self._schedule(now + TICK_NS, sleeping=False)
            return
        wake = self.input.source.next_change(now)
        if wake is not None:
            self._schedule(max(wake, now) + TICK_NS, sleeping=True)
        else:
            self._cancel()

    def _alpha(self) -> float:
        return min(1.0, self.motor.k(39) / 1024.0)

    def _filter(self, now: int) -> None:
        alpha = self._alpha()
        y = self.filtered
        for i in range(SAMPLES_PER_TICK):
            x = self.input.counts(now - (SAMPLES_PER_TICK - 1 - i) * SAMPLE_NS)
            y += alpha * (x - y)
        self.filtered = y

    def _settled(self, now: int) -> bool:
        alpha = self._alpha()
        if alpha == 0.0:
            return True                 # K39=0: the filter passes nothing
        x = self.input.counts(now)
        if abs(x - self.filtered) < SETTLED and not self.input.source.changing(now):
            self.filtered = float(x)
            return True
        return False

    def _busy(self, now: int) -> bool:
        if not self._settled(now):
            return True
        if self.mode == TORQUE_FEEDBACK:
            return self.feedback is not None
        if self.mode == TORQUE:
            return self._torque_busy()
        return self.mode in SPEED_MODES and self._waiting

    # -- helpers ------------------------------------------------------------------------
    def _owns(self) -> bool:
        return self._own is not None and self.motor.axis.profile is self._own

    def _limits(self, speed: float | None = None) -> Limits:
        m = self.motor
        accel = units.accel_to_pps2(m.k(43))
        return Limits(speed or k40_pps(m), accel, accel * m.k(44) / 100.0, 0.0, m.k(69))

    def _rebase(self) -> None:
        target = self.motor.axis.target()
        if not math.isfinite(target):
            target = self.motor.axis.position()
        self.base = (target, unipolar(self.filtered))

    def _apply(self) -> None:
        mode = self.mode
        if mode == POSITION:
            self._position()
        elif mode in SPEED_MODES:
            self._speed_control()
        elif mode == P_DATA:
            self._write_data("P", round(self.motor.k(41) * unipolar(self.filtered)))
        elif mode in (S_PLUS, S_MINUS, S_BOTH):
            self._s_data()
        elif mode == TORQUE:
            self._torque_control()
        elif mode == TORQUE_FEEDBACK:
            self._torque_feedback()

    # -- K38=1 position control ---------------------------------------------------------
    def _position(self) -> None:
        """Position in the K41 range around where the control started, while the motor
        is not running another motion (ch. 3 K38=1, K41)."""
        m = self.motor
        if not m.can_move() or (m.axis.moving and not self._owns()):
            self._rebase()
            return
        base, fraction = self.base
        target = round(base + m.k(41) * (unipolar(self.filtered) - fraction))
        if target == round(m.axis.target()):
            return
        if m.axis.nudge(float(target), float(m.k(55))):
            self._own = m.axis.profile
            return
        m.move_to([(float(target), self._limits())])
        self._own = m.axis.profile

    # -- K38=2,3,4 speed control --------------------------------------------------------
    def _speed_control(self) -> None:
        """Continuous rotation at up to K40; only after the input was once at zero speed."""
        m = self.motor
        y = self.filtered
        both = self.mode == SPEED_BOTH
        self._waiting = False
        if not self.armed:
            self.armed = self._zero_speed_input()
            if not self.armed:
                return
        fraction = bipolar(y) if both else unipolar(y) * (-1 if self.mode == SPEED_CCW else 1)
        speed = float(round(fraction * k40_pps(m)))
        if not m.can_move():
            self._speed = None
            return
        if m.axis.moving and not self._owns():
            self._waiting = speed != 0.0
            return
        if speed == self._speed and (self._owns() or speed == 0.0):
            return
        self._speed = speed
        if speed == 0.0:
            if m.axis.moving:
                m.axis.stop(self._limits().decel)
                self._own = m.axis.profile
            return
        m.axis.run(speed * m.axis.sign, self._limits(abs(speed)))
        self._own = m.axis.profile

    def _zero_speed_input(self) -> bool:
        """The input asks for 0 min⁻¹: below 0.2 V (types 2, 3), 2.4-2.6 V (type 4)."""
        y = self.filtered
        return MID_LO <= y <= MID_HI if self.mode == SPEED_BOTH else y <= LO

    # -- K38=5..8 direct-mode data --------------------------------------------------------
    def _write_data(self, kind: str, value: int) -> None:
        if value == self._data:
            return
        self._data = value
        if kind == "P":
            self.motor.memory.set("P", 0, value)
        else:
            self.motor.write_state("ST", value)

    def _s_data(self) -> None:
        y = self.filtered
        if self.mode == S_BOTH:
            fraction = bipolar(y)
        else:
            fraction = unipolar(y) * (-1 if self.mode == S_MINUS else 1)
        self._write_data("S", k40_s_value(self.motor, fraction))

    # -- K38=9 torque control ---------------------------------------------------------------
    def _torque_control(self) -> None:
        """Torque M0 x input (2.5 V = 0, ±M0 at 4.8/0.2 V) on the load; speed up to K40."""
        m = self.motor
        if not m.can_move() or (m.axis.moving and not self._owns()):
            self._torque = None
            return
        limit = abs(int(m.memory.get("M", 0)))
        percent = limit * bipolar(self.filtered)
        v0 = m.axis.command_velocity()
        v1, held = self._torque_step(percent, v0)
        self._torque = held
        if v1 == 0.0 and v0 == 0.0:
            return
        self._drive(v0, v1)

    def _torque_step(self, percent: float, v0: float) -> tuple[float, float]:
        """(speed after one tick, torque % the motor gives) for a commanded torque."""
        m = self.motor
        plant = m.plant
        ppr = m.resolution.pulses_per_rev
        # resisting torque in the user direction: a sensed spring load (raw, against its
        # push) less a constant load torque of the load model (raw, "+ pushes CW")
        load = m.axis.sign * (self.input.source_load_torque()
                              - getattr(plant, "load_torque", 0.0))
        tau = percent / 100.0 * plant.rated_torque - load
        friction = friction_nm(plant, v0, ppr)
        if v0 == 0.0 and abs(tau) <= plant.coulomb_friction:
            return 0.0, percent
        if v0 == 0.0:
            friction = math.copysign(plant.coulomb_friction, tau)
        accel = (tau - friction) / plant.inertia * ppr / (2 * math.pi)
        v1 = v0 + accel * TICK_NS / 1e9
        if v0 != 0.0 and (v1 < 0.0) != (v0 < 0.0):
            v1 = 0.0
        cap = k40_pps(m)
        if abs(v1) >= cap:
            v1 = math.copysign(cap, v1)
            need = friction_nm(plant, v1, ppr) + load
            return v1, 100.0 * need / plant.rated_torque
        return v1, percent

    def _torque_busy(self) -> bool:
        m = self.motor
        if self._torque is None or not self._owns():
            return False
        v = m.axis.command_velocity()
        return abs(v) < k40_pps(m) and (v != 0.0 or self._torque != 0.0) and \
            self._torque_step(self._torque, v)[0] != v

    def _drive(self, v0: float, v1: float) -> None:
        """One tick at constant acceleration from v0 to v1, then v1 until the next tick."""
        m = self.motor
        ax = m.axis
        now = self.kernel.now
        p = ax.to_raw(ax.command_position())
        s = ax.sign
        dt = TICK_NS / 1e9
        accel = (v1 - v0) / dt
        first = Segment(0.0, dt, p, s * v0, s * accel, 0.0)
        end = first.end_state()[0]
        segments = [first]
        if v1 != 0.0:
            segments.append(Segment(dt, math.inf, end, s * v1, 0.0, 0.0))
        ax.drive(Profile(now, segments, final_position=None if v1 else end))
        self._own = ax.profile

    # -- K38=10 torque feedback (5.5) --------------------------------------------------------
    def handles_go(self, target: float, limits: Limits) -> bool:
        """``^`` under K38=10: positioning with torque feedback (5.5); False otherwise."""
        if self.mode != TORQUE_FEEDBACK or target == units.CONTINUOUS:
            return False
        m = self.motor
        if not m.can_move():
            return True
        here = m.axis.command_position()
        if target == here:
            m.move_to([(target, limits)])
            return True
        self.feedback = _Feedback(target, limits.speed, 1 if target > here else -1, limits)
        self._own = None
        self.filtered = float(self.input.counts())
        self._cancel()
        self._tick()
        return True

    def sensor_value(self) -> float:
        """The torque sensor reading in V15 units: 100 x (V - K76) / K77 (5.5)."""
        volts = counts_to_volts(self.filtered)
        k77 = self.motor.k(77)
        if k77 == 0:
            return 0.0
        return 100.0 * (volts - self.motor.k(76) / 100.0) / (k77 / 100.0)

    def _torque_feedback(self) -> None:
        """PI on (V15 - sensor) sets the speed toward P0 (±S0); ends at P0 (5.5)."""
        fb = self.feedback
        m = self.motor
        if fb is None:
            return
        if not m.can_move() or (self._own is not None and not self._owns()):
            self.feedback = None
            return
        error = m.v_numeric(m.memory.get("V", 15)) - self.sensor_value()
        kp, ki = m.k(74) / 100.0, m.k(75) / 1000.0
        u = kp * error + ki * (fb.integral + error)
        if abs(u) < 100.0 or (u > 0) != (error > 0):
            fb.integral += error        # no integration while saturated (anti-windup)
        u = kp * error + ki * fb.integral
        speed = fb.direction * fb.speed * max(-1.0, min(1.0, u / 100.0))
        here = m.axis.command_position()
        remaining = (fb.target - here) * fb.direction
        if remaining <= max(speed * fb.direction, 0.0) * TICK_NS / 1e9:
            self.feedback = None
            m.move_to([(fb.target, fb.limits)])
            self._own = None
            return
        self._drive_at(speed)

    def _drive_at(self, speed: float) -> None:
        """The command runs at ``speed`` (user pps) from where it is now.  The same speed
        as the command of this feedback already has changes nothing: the command is not
        issued again (a standing command re-issued every tick was a new motion, so the
        motor reported ``Ux=8`` a thousand times a second while the sensor held it)."""
        ax = self.motor.axis
        if self._owns() and self._driven_speed == speed:
            return
        self._driven_speed = speed
        p = ax.to_raw(ax.command_position())
        if speed == 0.0:
            seg: list[Segment] = []
            ax.drive(Profile(self.kernel.now, seg, start_state=(p, 0.0, 0.0), final_position=p))
        else:
            ax.drive(Profile(self.kernel.now, [Segment(0.0, math.inf, p, ax.sign * speed,
                                                       0.0, 0.0)]))
        self._own = ax.profile

    # -- Ix while the control sets the torque ---------------------------------------------------
    def load_percent(self, t: int | None = None) -> float:
        """The torque (% of rated, user direction) a sensed load takes from the motor
        holding against it (a torque-sensor source; 0 otherwise)."""
        load = self.input.source_load_torque(t)
        if not load:
            return 0.0
        return 100.0 * self.motor.axis.sign * load / self.motor.plant.rated_torque

    def torque_percent(self) -> float | None:
        """The torque the control commands (type 9), or ``None`` (the servo's own)."""
        if self.mode == TORQUE and self._owns() and self._torque is not None:
            return self._torque
        return None
