"""Alarms out of the servo and load model: when each condition is reached, solved in advance.

Each alarm is a :class:`~coolmuscle.motor.motion.axis.Watcher` that asks the current
:class:`~coolmuscle.motor.motion.dynamics.Motion` for the first instant its condition holds
and raises the alarm then (cml-users-guide.txt ch. 3 K56, K57; 6.6 ?99):

* position error overflow (Ux=1): |Pe| beyond K56 × 100 pulses (CM1: K56 kpulses);
  not while pushing (4.1.4 sets the target behind the object) nor during a stopper
  origin search;
* over speed (Ux=2): |speed| beyond 1.2 × K40 (the motor's maximum speed, ch. 3 K40);
* overload (Ux=4): |torque| beyond the rated torque (Ix > 100) for more than K57 ms;
* temperature (Ux=128): the I²t model (:mod:`.thermal`) beyond its alarm level.

Power-module over current (64) and regeneration (2) come only from fault injection
(:mod:`.faults`).  What happens when an alarm latches (report, alarm output, motor free)
and how it clears is :meth:`Motor.raise_alarm` / :meth:`Motor.enable`
(docs/fidelity.md "Servo, load and alarms").
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar, Final

from mypy_extensions import mypyc_attr

from ..motion import expoly as xp
from ..motion.axis import Watcher
from ..motion.dynamics import Piece
from ..status import Ux

if TYPE_CHECKING:
    from ..core import MotorCore
    from ..motion.axis import Axis
    from ..motion.dynamics import Conditions

#: Over speed threshold as a multiple of K40 (docs/fidelity.md).
OVER_SPEED_FACTOR: Final = 1.2


def _beyond(f: Callable[[Piece], xp.F], limit: float) -> tuple[Conditions, Conditions]:
    """Alternatives for ``|f| > limit``."""
    return (lambda p: [xp.plus(f(p), -limit)],
            lambda p: [xp.plus(xp.scale(f(p), -1.0), -limit)])


def _constant_beyond(f: xp.F, limit: float) -> bool:
    """``f`` is a constant beyond ``±limit`` (a piece at the torque limit)."""
    return f[1] == f[2] == f[3] == f[4] == 0.0 and abs(f[0]) > limit


# compiled (coolmuscle/_accel.py): tests subclass it
@mypyc_attr(allow_interpreted_subclasses=True)
class _AlarmWatch(Watcher):
    """Base: watches only while the servo is on and this alarm is not latched."""

    bit: ClassVar[Ux] = Ux(0)
    mask: ClassVar[int] = int(Ux(0))

    def __init__(self, motor: MotorCore) -> None:
        self.motor = motor
        #: :attr:`mask` as an attribute of the watcher (asked at every motion: compiled,
        #: a class variable is looked up by name)
        self._mask = int(type(self).mask)
        #: The motor's K table, whose version says when :meth:`limit` is read again
        #: (:meth:`threshold`: every motion of a stream asks for it).
        self._params = motor.params
        self._version = -1
        self._limit = 0.0

    def limit(self) -> float:
        """The threshold of the alarm, from the K parameters (the watchers of a K
        threshold give theirs; the others do not ask for one)."""
        return 0.0

    def threshold(self) -> float:
        """:meth:`limit`, read again only when a K value changed."""
        version = self._params.version
        if version != self._version:
            self._limit = self.limit()
            self._version = version
        return self._limit

    def active(self, axis: Axis) -> bool:
        # the motor's alarms as its axis's servo (the motor itself): read through the
        # compiled base class, not the motor's protocol (a lookup by name)
        return axis.enabled and not axis.servo.alarm & self._mask   # int & int: no enum

    def fire(self, axis: Axis) -> None:
        del axis
        self.motor.raise_alarm(int(self.bit))


class PositionErrorWatch(_AlarmWatch):
    """Ux=1: |Pe| > K56 × 100 pulses (ch. 3 K56)."""

    bit: ClassVar[Ux] = Ux.POSITION_ERROR_OVERFLOW
    mask: ClassVar[int] = int(Ux.POSITION_ERROR_OVERFLOW)

    def limit(self) -> float:
        unit = 1000 if self.motor.firmware.name == "cm1" else 100
        return float(self.motor.k(56) * unit)

    def next_time(self, axis: Axis, after_ns: int) -> int | None:
        if not self.active(axis) or self.motor.position_error_exempt():
            return None
        limit, motion = self.threshold(), axis.motion
        if motion.peak("err") <= limit:       # every piece would be skipped
            return None
        return motion.first_of(after_ns, _beyond(Piece.err, limit), None,
                               lambda p: motion.reach(p, "err") <= limit)


class OverSpeedWatch(_AlarmWatch):
    """Ux=2: |speed| > 1.2 × K40 min⁻¹."""

    bit: ClassVar[Ux] = Ux.OVER_SPEED
    mask: ClassVar[int] = int(Ux.OVER_SPEED)

    def limit(self) -> float:
        """1.2 × K40 min⁻¹, in pulses/s of the current resolution (K37)."""
        ppr = self.motor.resolution.pulses_per_rev
        return OVER_SPEED_FACTOR * self.motor.k(40) * ppr / 60.0

    def next_time(self, axis: Axis, after_ns: int) -> int | None:
        if not self.active(axis):
            return None
        limit = self.threshold()
        motion = axis.motion
        if motion.peak("vel") <= limit:       # every piece would be skipped
            return None
        return motion.first_of(after_ns, _beyond(Piece.vel, limit), None,
                               lambda p: motion.reach(p, "vel") <= limit)


class OverloadWatch(_AlarmWatch):
    """Ux=4: the torque beyond rated (Ix > 100) for more than K57 ms (ch. 3 K57).

    The stretches beyond rated are walked on the motion at once: the instant the torque
    goes beyond rated, the instant it comes back, the next stretch ..., until one lasts
    K57 ms (the alarm) or the motion has none left.  The instants are those that one
    kernel event per crossing would find (each search starts 1 ns after the crossing
    before it, as a re-armed watcher does), without the events: a servo that touches
    the limit on every cycle of a csp stream (a new target every 1 ms) costs no event for it.
    The stretches found are kept, so that a re-solve in the middle of one carries its
    start on (:meth:`_since_at`)."""

    bit: ClassVar[Ux] = Ux.OVERLOAD
    mask: ClassVar[int] = int(Ux.OVERLOAD)

    def __init__(self, motor: MotorCore) -> None:
        super().__init__(motor)
        self.since: int | None = None
        #: [enter, back or None] of each stretch beyond rated found on the motion.
        self._walk: list[list[int | None]] = []

    def _rated(self, axis: Axis) -> float:
        per = axis.motion.drive.percent_per_accel
        return 100.0 / per if per > 0.0 else float("inf")

    def _since_at(self, now: int) -> int | None:
        """Where the stretch beyond rated that is on at ``now`` began (``None``: none)."""
        for enter, back in self._walk:
            if enter is not None and enter <= now and (back is None or back > now):
                return enter
        return None

    def next_time(self, axis: Axis, after_ns: int) -> int | None:
        if not self.active(axis):
            self.since, self._walk = None, []
            return None
        since = self.since = self._since_at(after_ns)
        rated = self._rated(axis)
        motion = axis.motion
        walk: list[list[int | None]] = [[since, None]] if since is not None else []
        self._walk = walk
        if since is None and motion.peak("torque") <= rated:   # the walk's first answer
            return None
        hold = self.motor.k(57) * 1_000_000 + 1
        t = after_ns
        while True:
            if since is None:
                if motion.peak("torque") <= rated:    # every piece would be skipped
                    return None
                since = motion.first_of(t, _beyond(lambda p: p.torque, rated), None,
                                        lambda p: motion.reach(p, "torque") <= rated,
                                        lambda p: _constant_beyond(p.torque, rated))
                if since is None:
                    return None
                walk.append([since, None])
                t = since + 1
            deadline = since + hold
            back = motion.first_of(t, (lambda p: [xp.plus(p.torque, rated),
                                                  xp.plus(xp.scale(p.torque, -1.0), rated)],),
                                   deadline, None,
                                   lambda p: motion.reach(p, "torque") < rated)
            if back is None or back > deadline:
                return max(deadline, t)
            walk[-1][1] = back
            since, t = None, back + 1

    def fire(self, axis: Axis) -> None:
        self.since, self._walk = None, []
        super().fire(axis)


class TemperatureWatch(_AlarmWatch):
    """Ux=128: the driver temperature above its alarm level (6.6 ?71, ?99)."""

    bit: ClassVar[Ux] = Ux.TEMPERATURE
    mask: ClassVar[int] = int(Ux.TEMPERATURE)

    def __init__(self, motor: MotorCore) -> None:
        super().__init__(motor)
        self._thermal = motor.thermal       # (read at every motion)

    def active(self, axis: Axis) -> bool:
        return not axis.servo.alarm & self._mask

    def next_time(self, axis: Axis, after_ns: int) -> int | None:
        if not self.active(axis):
            return None
        thermal = self._thermal
        return thermal.first_above(axis.motion, after_ns, thermal.alarm)


def alarm_watchers(motor: MotorCore) -> list[Watcher]:
    """The alarm watchers of one motor, in the order they are checked."""
    return [PositionErrorWatch(motor), OverSpeedWatch(motor), OverloadWatch(motor),
            TemperatureWatch(motor)]
