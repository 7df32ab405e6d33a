"""What a motor does around its motion: torque limit, alarms, push, origin search, travel
limits, temperature, faults and the machine it drives.

:class:`Supervisor` is built by the façade (:class:`~coolmuscle.motor.motor.Motor`) for
the motor it supervises, which it sees as :class:`~coolmuscle.motor.core.MotorCore`, as
every part of a motor does.  It owns :mod:`.alarms`, :mod:`.push`, :mod:`.origin`,
:mod:`.limits`, :mod:`.thermal`, :mod:`.faults` and :mod:`.sensors`, the wiring between
them and the motor, and what the motor's actions hand over to it:

* ``push_to(target, limits, via=())`` (2.2.2 "Q"/"Z", 4.1.4),
* ``origin_search()`` (``|``, input function 7, 5.3),
* ``set_torque_limit(percent)`` (``M``: 2.1.1 "Soon after setting M data..."),
* ``add_motion_listener(callback)`` / ``notify_motion_done(reason)``: a callback when a
  motion (move, push, origin search) completes,
* the drive the servo and load model runs with (:meth:`Supervisor.drive`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Final

from ...sim.memo import Key, Memo
from ..motion.dynamics import Drive
from ..motion.planner import Limits
from ..status import ALARM_BITS, Ux
from .alarms import alarm_watchers
from .faults import Faults
from .limits import TravelLimits
from .origin import OriginSearch, auto_start
from .push import ERROR, Push
from .sensors import Geometry
from .thermal import Thermal

if TYPE_CHECKING:
    from ..core import MotorCore

MotionListener = Callable[[str], None]

#: K parameters whose change re-solves the motion (limits, thresholds, resolution).
_RESOLVE_ON: Final = frozenset({37, 40, 47, 55, 56, 57, 60, 61})

#: CM2 driver temperature alarm (°C); CM1 uses K71 (Appendix A "Temperature limit").
CM2_TEMPERATURE_ALARM: Final = 85.0


class Supervisor:
    """Everything around the motion of one motor (built before its axis exists)."""

    def __init__(self, motor: MotorCore) -> None:
        self.motor = motor
        #: ``M`` (2.1.1): the torque limit, % of the maximum torque
        self.torque_limit = 100
        self.thermal = Thermal(alarm=self._temperature_alarm())
        self.thermal.reset(None, motor.kernel.now)
        self.faults = Faults(motor)
        self.travel = TravelLimits(motor)
        self.push = Push(motor)
        self.origin = OriginSearch(motor)
        self.geometry = Geometry()
        self.input_driven = [False] * (motor.io.input_count + 1)
        self._motion_listeners: list[MotionListener] = []
        #: The drives made from the plant as it is (:meth:`drive`), by what else they
        #: were made from.
        self._drives: Memo[Key, Drive] = Memo(64)
        #: The drive :meth:`drive` gave last and what it was made from (a stream asks at
        #: every target: the same values give it back without a key or a lookup).
        self._last_drive: Drive | None = None
        self._ppr, self._speed_limit = 0, 0
        self._limit = self._scale = self._extra = self._lo = self._hi = 0.0
        # What :meth:`drive` reads at every target of a stream, held here in their own
        # types (compiled, a read through the motor's protocol is a generic lookup): the
        # K table, the plant's torques (read again when the plant says it changed) and
        # K37's pulses per revolution (read again when a K value changed).
        self._params = motor.params
        self._peak_torque = motor.plant.peak_torque
        self._rated_torque = motor.plant.rated_torque
        self._ppr_now, self._ppr_version = 0, -1

    def attach(self) -> None:
        """Watch the axis: alarms, push, origin search (the heat: Motor.motion_ends)."""
        axis = self.motor.axis
        self.motor.plant.on_change = self._plant_changed
        for watcher in (*alarm_watchers(self.motor), self.push, self.origin):
            axis.add_watcher(watcher)

    def _temperature_alarm(self) -> float:
        if self.motor.firmware.name == "cm1":
            return float(self.motor.k(71))
        return CM2_TEMPERATURE_ALARM

    # -- the drive ---------------------------------------------------------------
    def drive(self) -> Drive:
        """Dynamics parameters now: plant, torque limit, machine, faults.

        The same values give the same (immutable) Drive object until a field of the
        plant changes: a move asks for it once, and the solved motions are looked up
        by it."""
        faults = self.faults
        if faults.power_cable_broken:
            limit = 0.0
        elif self.push.active:
            limit = self.push.level_percent()
        else:
            limit = self.torque_limit * self._peak_torque / 100.0
        ppr = self._pulses_per_rev()
        extra = faults.extra_load_percent / 100.0 * self._rated_torque
        scale, speed_limit = faults.speed_scale(), self._params.get(40)
        lo, hi = self.geometry.walls(ppr)
        last = self._last_drive
        if last is not None and ppr == self._ppr and limit == self._limit \
                and scale == self._scale and extra == self._extra and lo == self._lo \
                and hi == self._hi and speed_limit == self._speed_limit:
            return last
        key: Key = (ppr, limit, scale, extra, (lo, hi), speed_limit)
        found = self._drives.get(key)
        if found is None:
            found = self._drives.put(key, self.motor.plant.drive(
                ppr, limit_percent_of_rated=limit, enabled=True, speed_scale=scale,
                extra_load_nm=extra, walls=(lo, hi), speed_limit=speed_limit))
        self._last_drive = found
        self._ppr, self._limit, self._scale, self._extra = ppr, limit, scale, extra
        self._lo, self._hi, self._speed_limit = lo, hi, speed_limit
        return found

    def _pulses_per_rev(self) -> int:
        """K37's pulses per revolution (ch. 3 K37 table), read again after a K change."""
        version = self._params.version
        if version != self._ppr_version:
            self._ppr_now = self.motor.resolution.pulses_per_rev
            self._ppr_version = version
        return self._ppr_now

    def _plant_changed(self) -> None:
        """A field of the plant changed: new drives, and the motion re-solved at once."""
        plant = self.motor.plant
        self._peak_torque, self._rated_torque = plant.peak_torque, plant.rated_torque
        self._drives.clear()
        self._last_drive = None
        self.motor.axis.refresh()

    def set_torque_limit(self, percent: int) -> None:
        """``M`` (2.1.1): the torque limit, % of the maximum torque, applies at once."""
        percent = max(0, min(100, int(percent)))
        if percent != self.torque_limit:
            self.torque_limit = percent
            self.motor.axis.refresh()

    @property
    def push_error(self) -> bool:
        """The push error (Ux=256) is latched (4.1.4 "alarm state")."""
        return self.push.state == ERROR

    def param_changed(self, k: int) -> None:
        """K``k`` changed: K45 direction, CM1 K71 temperature alarm, re-solve on limits."""
        m = self.motor
        if k == 45:
            sign = -1 if m.k(45) % 10 >= 2 else 1
            if sign != m.axis.sign:
                m.axis.sign = sign
                m.axis.refresh()
        if k == 71 and m.firmware.name == "cm1":
            self.thermal.alarm = float(m.k(71))
        if k in _RESOLVE_ON or k == 71:
            m.axis.refresh()

    # -- temperature -------------------------------------------------------------------
    def set_temperature(self, celsius: float) -> None:
        """The case is at ``celsius`` now (fault injection, machine file)."""
        m = self.motor
        self.thermal.advance(m.axis.motion, m.kernel.now)
        self.thermal.reset(celsius, m.kernel.now)
        if celsius > self.thermal.alarm:
            m.raise_alarm(int(Ux.TEMPERATURE))
        m.axis.refresh()

    # -- actions -----------------------------------------------------------------
    def push_to(self, target: float, limits: Limits | None,
                via: Sequence[tuple[float, Limits | None]] = ()) -> bool:
        """Push motion toward user position ``target`` (4.1.4), merging through ``via``;
        False when it does not start.

        Zero speed data (no limits) means no motion (docs/fidelity.md "Motion")."""
        m = self.motor
        if not m.can_move() or limits is None:
            return False
        points: list[tuple[float, Limits]] = []
        for t, lim in (*via, (target, limits)):
            if lim is None:
                return False
            points.append((self.travel.clamp(t), lim))
        if self.travel.blocked(m.axis.to_raw(points[-1][0]) - m.axis.raw_command()):
            return False
        self.abandon_motion()
        self.push.start(points[-1][0], points[-1][1], points[:-1])
        return True

    def origin_search(self) -> None:
        """``|`` / input function 7: origin search (5.3)."""
        if not self.motor.can_move():
            return
        self.abandon_motion()
        self.origin.start()

    def stop_push(self) -> bool:
        """A stop while pushing: the shaft's position becomes the target (ch. 3 K55
        "the stopped position is recognized as the target position")."""
        if not self.push.active:
            return False
        self.abandon_motion()
        axis = self.motor.axis
        axis.follow(axis.position())
        return True

    def abandon_motion(self) -> None:
        """A push or origin search in progress ends without completing."""
        self.push.clear()
        self.origin.cancel()

    def allowed_target(self, user: float) -> float | None:
        """``user`` within the software limits, or None when a limit sensor refuses."""
        user = self.travel.clamp(user)
        axis = self.motor.axis
        if self.travel.blocked(axis.to_raw(user) - axis.raw_command()):
            return None
        return user

    def continuous_blocked(self, s_value: int, limits: Limits) -> bool:
        """Limit sensors refuse, software limits turn the rotation into a move (2.1.1)."""
        axis = self.motor.axis
        direction = axis.sign * (1 if s_value > 0 else -1 if s_value < 0 else 0)
        if self.travel.blocked(direction):
            return True
        lo, hi = self.travel.soft_range()
        stop_at = hi if s_value > 0 else lo if s_value < 0 else math.nan
        if math.isfinite(stop_at):
            axis.move([(stop_at, limits)])
            return True
        return False

    # -- completion ----------------------------------------------------------------
    def add_motion_listener(self, listener: MotionListener) -> Callable[[], None]:
        """Call ``listener(reason)`` whenever a motion completes; returns a remover.

        Reasons: ``in-position``, ``push-complete``, ``push-error``, ``origin-complete``,
        ``alarm``, ``free``.
        """
        self._motion_listeners.append(listener)

        def remove() -> None:
            if listener in self._motion_listeners:
                self._motion_listeners.remove(listener)
        return remove

    def notify_motion_done(self, reason: str) -> None:
        for listener in list(self._motion_listeners):
            listener(reason)
        self.motor.motion_settled()

    def push_finished(self, reason: str) -> None:
        """The push completed (Ux 40), failed (256) or ended at its target (8)."""
        m = self.motor
        if reason == "push-complete":
            m.axis.hold_here()
        else:
            m.axis.refresh()
        m.report_status()
        self.notify_motion_done(reason)

    def arrival(self) -> None:
        """In position at the end of a leg: the origin search, a push or a plain move."""
        if self.origin.active:
            self.origin.arrived()
        elif self.push.active:
            self.push.arrived()
        else:
            m = self.motor
            if not m.estopped and not m.alarm:   # those were reported when they began
                m.report_status()
            self.notify_motion_done("in-position")

    def alarm_latched(self, bits: int) -> bool:
        """Latch alarm ``bits``; False when nothing new."""
        m = self.motor
        bits &= int(ALARM_BITS)
        if not bits or m.alarm & bits == bits:
            return False
        m.alarm |= bits
        self.abandon_motion()
        m.axis.enabled = False
        m.report_status()
        self.notify_motion_done("alarm")
        return True

    def status(self) -> int | None:
        """Ux from the origin search and the push, or None."""
        if self.origin.active:
            return int(Ux.RUNNING)
        bits = self.push.status_bits()
        return bits or None

    # -- inputs ------------------------------------------------------------------------
    def input_level(self, number: int, on: bool) -> bool:
        """Record the driven level; returns the level the input shows (faults)."""
        if 1 <= number < len(self.input_driven):
            self.input_driven[number] = bool(on)
        return self.faults.input_level(number, bool(on))

    def refresh_inputs(self) -> None:
        """Re-apply the faults to every driven input level."""
        m = self.motor
        for number in range(1, m.io.input_count + 1):
            m.set_input_level(number, self.input_driven[number])

    def power_on(self) -> None:
        """Power-up: saved K45 / K71 take effect; odd K46 starts an origin search."""
        m = self.motor
        self.param_changed(45)
        self.thermal.alarm = self._temperature_alarm()
        if auto_start(m.k(46)) and m.axis.enabled:
            m.kernel.call_soon(self.origin_search, name="power-on origin search")
