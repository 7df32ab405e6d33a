"""Push motion ``Q``/``Z`` (cml-users-guide.txt 2.2.2 "Q", 4.1.4; ch. 3 K60, K61).

A push is a move toward a target within the push torque K60 (% of rated; CM1: % of
80 % of the full torque, cm1-ethernetip-interface-manual.txt Appendix A).  While it runs
Ux is 32 and the K34 function 9 output is on.  When the torque has stayed at the push
level for K61 ms the push is complete: Ux=40 (32 + in-position) is reported and the
motor holds where it pushed (the command becomes the actual position, the torque limit
returns to M).  K61=0 pushes without end.  Reaching the target first (nothing to push,
or the level too high to be reached) is the push error Ux=256 — unless K60 is odd, then
the push ends as a plain positioning (Ux=8).  The fidelity choices are in
docs/fidelity.md "Push".

The push state is also what a program bank waits on: :meth:`Motor.motion_done`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Final

from ...sim.kernel import PRIO_MOTION, Timer
from ..motion import expoly as xp
from ..motion.axis import Watcher
from ..motion.planner import Limits
from ..status import Ux

if TYPE_CHECKING:
    from ..core import MotorCore
    from ..motion.axis import Axis

APPROACH: Final = "approach"
PUSHING: Final = "pushing"
COMPLETE: Final = "complete"
ERROR: Final = "error"

#: Ux per push state (plain ints: read at every status report).
_STATUS_BITS: Final = {PUSHING: int(Ux.PUSH), COMPLETE: int(Ux.PUSH | Ux.IN_POSITION),
                       ERROR: int(Ux.PUSH_ERROR)}

#: The torque counts as "at the push level" within this relative margin.
_AT_LEVEL: Final = 1.0 - 1e-6


class Push(Watcher):
    """The push motion of one motor (a watcher on its axis)."""

    def __init__(self, motor: MotorCore) -> None:
        self.motor = motor
        self.state: str | None = None
        self.since: int | None = None
        self._action = ""
        self._begin_timer: Timer | None = None

    @property
    def active(self) -> bool:
        """A push is running (Ux 32, K34 function 9)."""
        return self.state == PUSHING

    @property
    def at_level(self) -> bool:
        """Pushing with the torque at the K60 level (CM1 K34 function 9, "Torque Limit
        reached - Push Mode Only", cm1-ethernetip-interface-manual.txt Appendix A)."""
        return self.state == PUSHING and self.since is not None

    def status_bits(self) -> int:
        """The Ux value the push contributes (6.6 ?99): 32, 40, 256 or 0."""
        return _STATUS_BITS.get(self.state or "", 0)

    def level_percent(self) -> float:
        """Push torque, % of rated torque (K60)."""
        k60 = float(self.motor.k(60))
        if self.motor.firmware.name == "cm1":
            return k60 * 0.8 * self.motor.plant.peak_torque / 100.0
        return k60

    def start(self, target: float, limits: Limits,
              via: Sequence[tuple[float, Limits]] = ()) -> None:
        """Push toward user position ``target`` (after merging through ``via``).

        With merge points before it (4.1.4 "S3.1, A1.1, P1.1, S1.1, Q2.1": "changes the
        speed to S1 at P1 and start performing Push Motion toward P2") the push begins
        when the motion passes the last of them; until then it is a plain move.
        """
        self.clear()
        axis = self.motor.axis
        self.state = APPROACH if via else PUSHING
        axis.move([*via, (target, limits)])
        if not via:
            return
        passing = [t for t, index in axis.profile.passing_times_ns() if index == len(via) - 1]
        if passing:
            self._begin_timer = self.motor.kernel.schedule_at(
                max(passing[0], self.motor.kernel.now), self._begin, priority=PRIO_MOTION,
                name="push-begins")
        else:
            self._begin()

    def _begin(self) -> None:
        """The last merge point is passed: the push proper starts (K60 torque)."""
        self._begin_timer = None
        if self.state == APPROACH:
            self.state, self.since = PUSHING, None
            self.motor.axis.refresh()

    def clear(self) -> None:
        """Forget the push (a new motion, stop, free, alarm)."""
        self.state, self.since = None, None
        if self._begin_timer is not None:
            self._begin_timer.cancel()
            self._begin_timer = None

    # -- watcher --------------------------------------------------------------
    def next_time(self, axis: Axis, after_ns: int) -> int | None:
        if self.state != PUSHING or not axis.enabled:
            return None
        per = axis.motion.drive.percent_per_accel
        level = self.level_percent() / per * _AT_LEVEL if per > 0 else float("inf")
        at_level = (lambda p: [xp.plus(p.torque, -level)],
                    lambda p: [xp.plus(xp.scale(p.torque, -1.0), -level)])
        if self.since is None:
            self._action = "touch"
            return axis.motion.first(after_ns, *at_level)
        hold_ms = self.motor.k(61)
        endless = hold_ms == 0 or (self.motor.firmware.name == "cm1" and hold_ms >= 30001)
        deadline = None if endless else self.since + hold_ms * 1_000_000
        back = axis.motion.first(after_ns, lambda p: [xp.plus(p.torque, level),
                                                      xp.plus(xp.scale(p.torque, -1.0), level)],
                                 horizon_ns=deadline)
        if back is not None and (deadline is None or back <= deadline):
            self._action = "release"
            return back
        if deadline is None:
            return None
        self._action = "complete"
        return max(deadline, after_ns)

    def fire(self, axis: Axis) -> None:
        del axis
        now = self.motor.kernel.now
        if self._action == "touch":
            self.since = now
        elif self._action == "release":
            self.since = None
        else:
            self._complete()

    def _complete(self) -> None:
        self.state, self.since = COMPLETE, None
        self.motor.push_finished(int(Ux.PUSH | Ux.IN_POSITION), "push-complete")

    def arrived(self) -> None:
        """The target was reached while pushing (4.1.4): push error unless K60 is odd."""
        if self.motor.k(60) % 2 == 1:
            self.state, self.since = None, None
            self.motor.push_finished(int(Ux.IN_POSITION), "in-position")
            return
        self.state, self.since = ERROR, None
        self.motor.push_finished(int(Ux.PUSH_ERROR), "push-error")
