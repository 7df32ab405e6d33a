"""Travel limits: software limits K58/K59 and the CW/CCW limit sensors.

* Software limits (cml-users-guide.txt ch. 3 K58, K59, unit: K45 third digit; CM1 100
  pulses): "to prevent the motion over the set position".  A target beyond a limit is
  clamped to it, so the motor decelerates to stop exactly there (no message: the
  manual lists none); continuous rotation stops at the limit of its direction.  0 means
  no limit.  The origin search ignores them (docs/fidelity.md "Motion").
* Limit sensors (ch. 3 K27 input functions 6 "CW direction limit sensor" and 9 "CCW";
  K23 messages ``error07.n: CW Limit!!`` / ``error08.n: CCW Limit!!``): when one comes on
  while the shaft moves toward it the motor stops at maximum deceleration and reports
  the error; while it is on, a motion toward it is refused with the same error.  "Moves
  toward it": a motion commanded that way, or the shaft turning that way at
  :data:`AT_REST_PPS` or more (a servo settles exponentially: the last fraction of a
  pulse a second of a finished move is a shaft at rest, Ux=8, Sx=0).  CW is
  the raw (machine) positive direction.  :meth:`TravelLimits.sensor` is what the input
  function engineer and the machine file call (``Motor.limit_sensor``); it is idempotent.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final

from ...errors import CcwLimitError, CwLimitError, MotorError
from ..motion import planner
from ..signals.io import digit

if TYPE_CHECKING:
    from ..core import MotorCore

_UNIT: Final = {0: 100, 1: 10, 2: 1}
AT_REST_PPS: Final = 1.0   # below 1 pulse/s the shaft counts as standing (no pulse in a second)


class TravelLimits:
    """Software limits and limit-sensor state of one motor."""

    def __init__(self, motor: MotorCore) -> None:
        self.motor = motor
        self.on = {1: False, -1: False}
        self._range: tuple[float, float] = (-math.inf, math.inf)
        self._range_version = -1            # K45, K58, K59 as of this params version
        self._params = motor.params         # (its version is read at every target)

    # -- software limits ----------------------------------------------------------
    def soft_range(self) -> tuple[float, float]:
        """(lowest, highest) user position allowed; ±inf where K58/K59 are 0."""
        m = self.motor
        version = self._params.version
        if version != self._range_version:
            unit = 100 if m.firmware.name == "cm1" else _UNIT.get(digit(m.k(45), 3), 100)
            k58, k59 = m.k(58), m.k(59)
            self._range = (k59 * unit if k59 < 0 else -math.inf,
                           k58 * unit if k58 > 0 else math.inf)
            self._range_version = version
        return self._range

    def clamp(self, user_target: float) -> float:
        """A target within the software limits."""
        lo, hi = self.soft_range()
        return min(max(user_target, lo), hi)

    # -- limit sensors --------------------------------------------------------------
    @staticmethod
    def error(direction: int) -> MotorError:
        return CwLimitError() if direction > 0 else CcwLimitError()

    def sensor(self, direction: int, on: bool) -> None:
        """Limit sensor ``direction`` (+1 CW, -1 CCW) changed to ``on``."""
        direction = 1 if direction > 0 else -1
        if self.on[direction] == bool(on):
            return
        self.on[direction] = bool(on)
        m = self.motor
        if not on or m.origin.on_limit(direction):
            return
        if m.axis.raw_velocity() * direction >= AT_REST_PPS or self._heading(direction):
            m.abandon_motion()
            m.axis.stop(planner.ESTOP_DECEL)
            m.report_error(None, self.error(direction))

    def _heading(self, direction: int) -> bool:
        axis = self.motor.axis
        return axis.moving and (axis.target_raw - axis.raw_actual()) * direction > 0.0

    def blocked(self, raw_direction: float) -> bool:
        """Whether a motion in ``raw_direction`` is refused now (reports the error)."""
        if raw_direction == 0.0:
            return False
        direction = 1 if raw_direction > 0 else -1
        if self.on[direction]:
            self.motor.report_error(None, self.error(direction))
            return True
        return False
