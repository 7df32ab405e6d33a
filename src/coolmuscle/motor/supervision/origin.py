"""Origin search (cml-users-guide.txt 5.3; ch. 3 K27, K42, K43, K45, K46, K47, K48).

The ``|`` command and the input function "start origin search" (K28/K29/K31/K32 = 7)
call :meth:`OriginSearch.start`; odd K46 starts one at power-up.  The search is a small
state machine driven by the axis (in-position of each leg, :class:`Watcher` instants
for the stopper and the Z phase) and by the motor's input changes:

* stopper (K46 0/1, 5.3.1): run toward the K45 direction at K42/K43 until the torque
  reaches K47 while the speed is below K42/16; the contact point's encoder phase
  (0..999 per 1/50 turn) is the one reported; the motor backs off to that phase's 0
  point, away from the stopper ("1 cycle ahead");
* sensor (2/3), Z phase (4/5), sensor AND Z phase (6/7) (5.3.2, 5.3.3): with the signal
  on at the start, first run the other way until it goes off; then run toward K45
  until it comes on (point a), decelerate, stop, return to a.  A limit sensor of the
  search direction met on the way reverses the run at twice K42 until the signal is
  found, then goes on as from "signal on".  Without an origin sensor input (K27 = 2)
  the limit sensor of the search direction is the origin sensor (ch. 3 K27 6/9);
* then the offset K48 (unit: K45 second digit) at K42, reverse coordinates (K45 first
  digit 2/3) take effect, that point becomes 0, ``Origin.n=<phase>`` and ``Ux.n=8``
  are reported (K23 function 1) and "origin search completed" (K34 = 4) is set.

CW is the raw (machine) positive direction.  Choices: docs/fidelity.md "Origin search".
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final

from ..motion import expoly as xp
from ..motion.axis import Watcher
from ..signals.io import digit
from ..status import Report

if TYPE_CHECKING:
    from ..core import MotorCore
    from ..motion.axis import Axis

STOPPER: Final = "stopper"
SENSOR: Final = "sensor"
ZPHASE: Final = "z"
SENSOR_Z: Final = "sensor+z"

#: Encoder phase cycles per turn (5.3.1 "0 to 999 per 1/50 rotation").
PHASE_CYCLES: Final = 50

_LENGTH_UNIT: Final = {0: 100, 1: 10, 2: 1}

#: An edge counts as crossed this far past it (pulses): no chatter from float noise.
EDGE_MARGIN: Final = 1e-6


def source_of(k46: int) -> str:
    """K46 -> the origin signal source (CM1 16..19 behave as 0..3)."""
    return (STOPPER, SENSOR, ZPHASE, SENSOR_Z)[(k46 % 16) // 2 % 4]


def auto_start(k46: int) -> bool:
    """Odd K46 starts a search at power-up (CM1: 16..19 never do)."""
    return k46 < 16 and k46 % 2 == 1


class OriginSearch(Watcher):
    """The origin search of one motor (a watcher on its axis)."""

    def __init__(self, motor: MotorCore) -> None:
        self.motor = motor
        self.phase: str | None = None
        self.direction = 1
        self.source = STOPPER
        self.point: float | None = None
        self.reported_phase = 0
        self.signal_on = False
        self._z_on = False
        self._z_edges: tuple[float, float] = (math.inf, -math.inf)

    @property
    def active(self) -> bool:
        return self.phase is not None

    # -- parameters -----------------------------------------------------------------
    def _k45(self, position: int) -> int:
        return digit(self.motor.k(45), position)

    def _speed_pps(self, factor: float = 1.0) -> float:
        return self.motor.k(42) * self.motor.resolution.speed_unit_pps * factor

    def _limits(self, factor: float = 1.0):  # type: ignore[no-untyped-def]
        return self.motor.limits(int(self.motor.k(42) * factor), self.motor.k(43))

    def offset_pulses(self) -> float:
        """K48 in pulses (unit: K45 second digit; CM1 always 100 pulses)."""
        unit = 100 if self.motor.firmware.name == "cm1" else _LENGTH_UNIT.get(
            self._k45(2), 100)
        return float(self.motor.k(48) * unit)

    # -- start and stop -------------------------------------------------------------------
    def start(self) -> None:
        """``|``: begin the search (5.3)."""
        m = self.motor
        m.origin_done = False
        self.direction = 1 if self._k45(1) in (0, 2) else -1
        self.source = source_of(m.k(46))
        self.point = None
        self._z_reset()
        self.signal_on = self.signal()
        if self.source == STOPPER:
            self._leg("stopper", self.direction)
        elif self.signal_on:
            self._leg("leave", -self.direction)
        else:
            self._leg("seek", self.direction)

    def cancel(self) -> None:
        """Abandon the search (stop, free, alarm, a new motion)."""
        self.phase = None

    def _leg(self, phase: str, direction: int, factor: float = 1.0) -> None:
        self.phase = phase
        axis = self.motor.axis
        axis.run(axis.sign * direction * self._speed_pps(factor), self._limits(factor))

    def _stop(self, phase: str) -> None:
        self.phase = phase
        lim = self._limits()
        self.motor.axis.stop(lim.decel, lim.scurve)

    def _goto(self, phase: str, raw: float) -> None:
        self.phase = phase
        axis = self.motor.axis
        axis.move([(axis.to_user(raw), self._limits())])

    # -- the origin signal ----------------------------------------------------------------
    def sensor_input(self) -> int | None:
        """The origin sensor input: K27 = 2, else the search direction's limit (6/9)."""
        io = self.motor.io
        k27 = self.motor.k(27)
        for function in (2, 6 if self.direction > 0 else 9):
            for n in range(1, io.input_count + 1):
                if digit(k27, n) == function:
                    return n
        return None

    def signal(self) -> bool:
        """The origin signal now (sensor, Z phase, or both)."""
        sensor = self.source in (SENSOR, SENSOR_Z)
        zphase = self.source in (ZPHASE, SENSOR_Z)
        if sensor:
            n = self.sensor_input()
            if n is None or not self.motor.io.input_signal(n):
                return False
        return not zphase or self._z_on

    def on_input(self, number: int) -> None:
        """An input signal changed (the motor calls this on every change)."""
        if self.active and self.source in (SENSOR, SENSOR_Z) and number == self.sensor_input():
            self._signal_changed()

    def on_limit(self, direction: int) -> bool:
        """A limit sensor came on during the search; True when the search handled it.

        The search direction's limit reverses a seeking run (or is the origin sensor);
        the opposite limit abandons the search (the motor then stops as at any limit).
        """
        if not self.active:
            return False
        if direction != self.direction:
            self.cancel()
            return False
        if self.source in (SENSOR, SENSOR_Z) and self._limit_is_sensor(direction):
            return True
        if self.phase == "seek":
            self._leg("reverse", -self.direction, 2.0)
        return True

    def _limit_is_sensor(self, direction: int) -> bool:
        n = self.sensor_input()
        return n is not None and digit(self.motor.k(27), n) == (6 if direction > 0 else 9)

    def _signal_changed(self) -> None:
        on = self.signal()
        if on == self.signal_on:
            return
        self.signal_on = on
        if on and self.phase == "seek":
            self.point = self.motor.axis.raw_actual()
            self._stop("seek-stop")
        elif on and self.phase == "reverse":
            self._leg("leave", -self.direction)
        elif not on and self.phase == "leave":
            self._stop("leave-stop")

    # -- the axis: arrivals and watched instants ---------------------------------------------
    def arrived(self) -> None:
        """The axis is in position at the end of a leg."""
        if self.phase == "leave-stop":
            self._leg("seek", self.direction)
        elif self.phase == "seek-stop" and self.point is not None:
            self._goto("return", self.point)
        elif self.phase in ("return", "back"):
            self._mechanical_origin()
        elif self.phase == "offset":
            self._finish()

    def next_time(self, axis: Axis, after_ns: int) -> int | None:
        if self.phase == "stopper":
            return self._stopper_time(axis, after_ns)
        if self.phase in ("seek", "leave", "reverse") and self.source in (ZPHASE, SENSOR_Z):
            up, down = self._z_edges
            up, down = up + EDGE_MARGIN, down - EDGE_MARGIN
            return axis.motion.first(after_ns, lambda p: [xp.plus(p.pos, -up)],
                                     lambda p: [xp.plus(xp.scale(p.pos, -1.0), down)])
        return None

    def fire(self, axis: Axis) -> None:
        if self.phase == "stopper":
            self.point = axis.raw_actual()
            axis.hold_here()
            self._goto("back", self._phase_zero(self.point))
            return
        self._z_cross(axis.raw_actual())
        self._signal_changed()

    def _stopper_time(self, axis: Axis, after_ns: int) -> int | None:
        per = axis.motion.drive.percent_per_accel
        if per <= 0:
            return None
        level = self.motor.k(47) / per * (1.0 - 1e-9)
        slow = self._speed_pps() / 16.0
        still = (lambda p: xp.plus(p.vel(), slow), lambda p: xp.plus(xp.scale(p.vel(), -1.0), slow))
        return axis.motion.first(
            after_ns,
            lambda p: [xp.plus(p.torque, -level), still[0](p), still[1](p)],
            lambda p: [xp.plus(xp.scale(p.torque, -1.0), -level), still[0](p), still[1](p)])

    # -- encoder phase and Z phase -----------------------------------------------------------
    def _cycle(self) -> float:
        return self.motor.resolution.pulses_per_rev / PHASE_CYCLES

    def encoder_phase(self, raw: float) -> int:
        """Encoder phase 0..999 of a raw position (5.3.1)."""
        cycle = self._cycle()
        frac = (round(raw - self.motor.z_position(), 3) % cycle) / cycle
        return min(999, int(frac * 1000))

    def _phase_zero(self, raw: float) -> float:
        """The phase-0 point within one cycle of ``raw``, away from the stopper."""
        cycle, z0 = self._cycle(), self.motor.z_position()
        n = (raw - z0) / cycle
        whole = math.floor(n) if self.direction > 0 else math.ceil(n)
        return z0 + whole * cycle

    def _z_reset(self) -> None:
        """Z window state and its next edges above and below the shaft."""
        x = self.motor.axis.raw_actual()
        ppr, z0, w = self.motor.resolution.pulses_per_rev, self.motor.z_position(), self._cycle()
        base = z0 + math.floor((x - z0) / ppr) * ppr
        self._z_on = x - base < w
        self._z_edges = (base + w, base) if self._z_on else (base + ppr, base + w)

    def _z_cross(self, x: float) -> None:
        up, down = self._z_edges
        ppr, w = self.motor.resolution.pulses_per_rev, self._cycle()
        self._z_on = not self._z_on
        if abs(x - up) <= abs(x - down):
            self._z_edges = (up + (w if self._z_on else ppr - w), up)
        else:
            self._z_edges = (down, down - (w if self._z_on else ppr - w))

    # -- the end ----------------------------------------------------------------------------
    def _mechanical_origin(self) -> None:
        if self.point is not None:
            self.reported_phase = self.encoder_phase(self.point)
        offset = self.offset_pulses()
        if offset:
            sign = -1 if self._k45(1) >= 2 else 1
            self._goto("offset", self.motor.axis.target_raw + sign * offset)
        else:
            self._finish()

    def _finish(self) -> None:
        m = self.motor
        self.phase = None
        axis = m.axis
        axis.sign = -1 if self._k45(1) >= 2 else 1
        axis.zero = axis.target_raw
        axis.refresh()
        m.origin_done = True
        if m.reports(Report.IN_POSITION_AND_ALARM):
            m.bus.emit(m.id, "origin", f"Origin.{m.id}={self.reported_phase}",
                       value=self.reported_phase)
        m.report_status()
        m.notify_motion_done("origin-complete")
