"""Manual jog and manual feed (cml-users-guide.txt 5.1; ch. 3 K27-K32, K43, K49, K50).

The input functions call these through :meth:`Motor.jog`, :meth:`Motor.feed` and
:meth:`Motor.feed_stop` (K28/K29/K31/K32 = 8/9 jog, K27/K30 = 3/4 feed).

* **Jog** moves K50 pulses per one-shot signal.  Table 6.1 (K50): "Speed and
  acceleration are set automatically and can not be changed": the jog runs at one
  revolution per second with 100 kpps² (no creep speed, no S-curve), whatever S,
  A, K49, K43, K51 and K69 say (docs/fidelity.md "Motion").  A jog while the
  motor moves is ignored.
* **Feed** turns CW/CCW at K49 with K43 (K44 for the deceleration, K51, K69 as
  for every motion) while the signal is on, and decelerates when it goes off.
  5.1: "If a motion is stopped by an alarm or stop command ... cancel an alarm
  then turn signal off then back on": a feed that was interrupted, or that could
  not start, stays blocked until :meth:`feed_stop` (signal off).

CW is the physical direction (raw encoder pulses increasing); with reverse
coordinates (K45) it is the negative user direction.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..motion.planner import Limits
from ..motion.profile import Profile

if TYPE_CHECKING:
    from ..core import MotorCore

#: Jog speed: one revolution per second (60 min⁻¹) at any resolution.
JOG_REV_PER_S = 1.0
#: Jog acceleration and deceleration, pulses/s² (table 6.1's K43 default, 100 kpps²).
JOG_ACCEL = 100_000.0


class ManualMotion:
    """Jog and feed state of one motor."""

    def __init__(self, motor: MotorCore) -> None:
        self.motor = motor
        self.feed_profile: Profile | None = None
        self.feed_direction = 0
        self.blocked = False

    def _user(self, direction: int) -> int:
        """CW (+1) / CCW (-1) as a user-coordinate direction."""
        return direction * self.motor.axis.sign

    def jog_limits(self) -> Limits:
        """The automatic jog speed and acceleration (table 6.1 K50)."""
        speed = JOG_REV_PER_S * self.motor.resolution.pulses_per_rev
        return Limits(speed, JOG_ACCEL, JOG_ACCEL)

    def jog(self, direction: int) -> bool:
        """One jog step of K50 pulses CW (+1) or CCW (-1); returns whether it started."""
        m = self.motor
        if direction not in (1, -1) or not m.can_move() or m.axis.moving:
            return False
        target = m.axis.target() + self._user(direction) * m.k(50)
        m.move_to([(target, self.jog_limits())])
        return True

    def feeding(self) -> bool:
        """Whether the feed motion this object started is still the running one."""
        return self.feed_profile is not None and self.motor.axis.profile is self.feed_profile

    def feed(self, direction: int) -> bool:
        """Feed signal on: rotate CW (+1) / CCW (-1); returns whether the motor feeds."""
        if direction not in (1, -1):
            return False
        if self.feeding():
            return True
        m = self.motor
        if self.feed_profile is not None or self.blocked or not m.can_move() or m.axis.moving:
            self.blocked = True      # interrupted, or refused: wait for signal off (5.1)
            return False
        m.run_continuous(self._user(direction) * m.k(49), m.limits(m.k(49), m.k(43)))
        self.feed_profile = m.axis.profile
        self.feed_direction = direction
        return True

    def feed_stop(self) -> None:
        """Feed signal off: decelerate (K43, K44) if still feeding; unblock."""
        m = self.motor
        if self.feeding():
            lim = m.limits(m.k(49), m.k(43))
            assert lim is not None                # K43 and K49 are at least 1 (ch. 3)
            m.axis.stop(lim.decel, lim.scurve, creep=lim.creep, speed=lim.speed)
        self.feed_profile = None
        self.feed_direction = 0
        self.blocked = False
