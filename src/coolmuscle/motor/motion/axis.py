"""The servo axis: the commanded trajectory, the actual shaft motion, and motion milestones.

The command is a closed-form :class:`~coolmuscle.motor.motion.profile.Profile`; the shaft
follows it through :class:`~coolmuscle.motor.motion.dynamics.Motion` (tracking error, torque
limit, load, stoppers, servo off).  Whenever the command or the drive changes the axis
re-solves the motion from the current actual state and schedules one kernel event per
milestone: in-position, merge passing points, and whatever its *watchers* ask for
(alarms, sensor edges, push and origin-search detection; see :class:`Watcher`).  A
move costs a handful of events, not a tick per millisecond.

Coordinates: the axis works in raw encoder pulses (the machine file's coordinates,
docs/machine-file.md); the user coordinate is ``sign * (raw - zero)``: ``|2`` moves
``zero`` (2.1.2), reverse coordinates (K45 first digit 2/3, ch. 3 K45) flip ``sign``.

In-position (ch. 3 K55, Ux=8) is declared when the actual position is within K55 of the
target, on the command's final approach: possibly before the command has ended
(docs/fidelity.md "Servo, load and alarms").
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from functools import partial

from mypy_extensions import mypyc_attr

from ...sim.kernel import PRIO_HORIZON, PRIO_MOTION, Kernel, Timer
from . import planner
from .dynamics import LOST, Drive, Motion, MotionMemos
from .planner import Limits, Waypoint
from .profile import Profile, Segment, hold, stops_then_restarts

log = logging.getLogger(__name__)


# compiled (coolmuscle/_accel.py): a base class, not a protocol, so that the axis calls
# its methods directly at every motion; subclassable by interpreted code (tests)
@mypyc_attr(allow_interpreted_subclasses=True)
class Watcher:
    """Something that wants a kernel event when the motion reaches a condition (the
    alarms, the push, the origin search, position sensors subclass it)."""

    def next_time(self, axis: Axis, after_ns: int) -> int | None:
        """The next instant >= ``after_ns`` to call :meth:`fire` (``None``: never).  It
        only looks: it adds or removes no watcher."""
        del axis, after_ns
        return None

    def fire(self, axis: Axis) -> None:
        """The instant has come (it may change the command or the drive)."""
        del axis


# compiled (coolmuscle/_accel.py): a base class, so that the axis calls the motor's
# answers directly at every motion; subclassable by interpreted code (tests)
@mypyc_attr(allow_interpreted_subclasses=True)
class Servo:
    """What an axis asks of the motor it turns (:class:`coolmuscle.motor.motor.Motor`
    subclasses it); this base is a bare shaft: a stiff loop, a K55 of 5 pulses."""

    #: The motor's latched alarms (Ux bits, 6.6 ?99; 0: none): the alarm watchers of
    #: its axis read them at every motion.
    alarm: int = 0

    def drive(self) -> Drive:
        """The dynamics parameters now (plant, torque limit, machine, faults)."""
        return Drive(kp=300.0, a_limit=1e12, a_friction=0.0, a_load=0.0, v_max=1e12)

    def in_position_window(self) -> int:
        """K55 (ch. 3), pulses."""
        return 5

    def motion_ends(self, motion: Motion, now: int) -> None:
        """``motion`` is replaced at ``now`` (before each re-solve: the thermal model
        brings its state to ``now`` along it)."""
        del motion, now

    def in_position(self) -> None:
        """The shaft came within K55 of the target (Ux=8)."""

    def passing_point(self, index: int) -> None:
        """A merge passing point ``index`` was passed (K34=6, K73)."""
        del index


class Axis:
    """One motor shaft under position control."""

    def __init__(self, kernel: Kernel, servo: Servo | None = None, *,
                 memos: MotionMemos | None = None) -> None:
        self.kernel = kernel
        #: Plans and solved motions, shared with the other axes of the chain.
        self.memos = MotionMemos() if memos is None else memos
        self.servo = Servo() if servo is None else servo
        self.zero = 0.0
        self.sign = 1
        #: Half the span of the position counter (user pulses): user positions wrap
        #: round past it (:func:`wrap_user`; inf: never).
        self.half_range = math.inf
        self._enabled = True
        self.profile: Profile = hold(0.0, kernel.now)
        #: (profile, rest): after a reversal restarted at rest (:meth:`move`), the plan
        #: from rest that the shaft follows from its origin on, while ``profile`` is
        #: still the one planned then.
        self._rest: tuple[Profile, Profile] | None = None
        self.motion = Motion(self.profile, kernel.now, 0.0, 0.0, self.servo.drive(),
                             self.memos)
        self.target_raw = 0.0
        #: The command of a stream (:meth:`follow`) and when its next target is due:
        #: while it is followed, the motion is solved that far only (dynamics.Motion).
        #: Two attributes, not a tuple: compiled, the instant stays unboxed.
        self._stream: Profile | None = None
        self._stream_due = 0
        #: Solve every motion to its end at once, a stream's too (the same numbers and
        #: instants, only slower: tests compare the two).
        self.solve_in_full = False
        self.moving = False
        self.generation = 0
        self._watchers: list[Watcher] = []
        self._timers: list[Timer] = []
        #: A reversal after an early in-position is solved from the command's end
        #: (:meth:`move`; False: from the decelerating command now, the exact oracle).
        self.restart_at_rest = True
        #: The kernel event of each watcher, by its place in :attr:`watchers` (``None``:
        #: it asked for none).
        self._watch_timers: list[Timer | None] = []
        #: Where the part of the motion solved ends, while the axis waits there
        #: (:meth:`_arm_all`; ``None``: solved to its end, or a new motion came).
        self._frontier_at: int | None = None
        #: :meth:`_frontier_due` as the kernel calls it (made once: a bound method made
        #: at every stream target is an allocation and a lookup)
        self._on_frontier = self._frontier_due
        #: (time_ns, profile, motion, zero, sign) kept while a trace records.
        self.history: list[tuple[int, Profile, Motion, float, int]] | None = None
        #: Called after every trajectory change (rotation pulses, external encoder:
        #: :class:`coolmuscle.motor.motion.trajectory.Timeline`).
        self.trajectory_listeners: list[Callable[[], None]] = []

    @property
    def watchers(self) -> tuple[Watcher, ...]:
        """The watchers, in the order those due at one instant fire (:meth:`add_watcher`,
        :meth:`remove_watcher`)."""
        return tuple(self._watchers)

    @property
    def tracking(self) -> Motion:
        """The shaft motion (kept under its former name for trace code)."""
        return self.motion

    # -- coordinates ------------------------------------------------------
    def to_raw(self, user: float) -> float:
        """User pulses -> raw pulses.  The user value counts in the counter's current
        turn, the one the shaft is in (after a wrap, P0 is the counter's 0 there)."""
        return self.zero + self.sign * (user + self._turn())

    def _turn(self) -> float:
        """Where the counter's current turn starts, in unwrapped user pulses (0 until
        the position first wraps round)."""
        if self.half_range == math.inf:
            return 0.0
        here = self.sign * (self.raw_actual() - self.zero)
        return here - wrap_user(here, self.half_range)

    def to_user(self, raw: float) -> float:
        """Raw pulses -> user pulses, as the position counter shows them (wrapped)."""
        return wrap_user(self.sign * (raw - self.zero), self.half_range)

    # -- live values (closed form at kernel.now) --------------------------
    def raw_command(self) -> float:
        return self.motion.command_at(self.kernel.now)

    def raw_actual(self) -> float:
        return self.motion.position_at(self.kernel.now)

    def raw_velocity(self) -> float:
        return self.motion.velocity_at(self.kernel.now)

    def position(self) -> float:
        """Actual position, user pulses (?96)."""
        return self.to_user(self.raw_actual())

    def command_position(self) -> float:
        """Commanded position now, user pulses."""
        return self.to_user(self.raw_command())

    def target(self) -> float:
        """Target position PT, user pulses."""
        return self.to_user(self.target_raw)

    def position_error(self) -> float:
        """Pe, pulses (?95), in the user direction."""
        return self.sign * self.motion.error_at(self.kernel.now)

    def velocity(self) -> float:
        """Actual speed, user pulses/s (?97 before unit conversion)."""
        return self.sign * self.raw_velocity()

    def torque_percent(self) -> float:
        """Motor torque, % of rated, in the user direction (?98)."""
        return self.sign * self.motion.torque_percent_at(self.kernel.now)

    def command_velocity(self) -> float:
        return self.sign * self.profile.velocity_at(self.kernel.now)

    def mode(self) -> str:
        """The dynamics mode now (``track``, ``sat``, ``contact``, ...)."""
        return self.motion.mode_at(self.kernel.now)

    def _raw_state(self) -> tuple[float, float, float]:
        now = self.kernel.now
        if not self._enabled or self.motion.mode_at(now) == LOST:
            return self.raw_actual(), self.raw_velocity(), 0.0
        return self._command_state(now)

    def _command_state(self, t_ns: int) -> tuple[float, float, float]:
        """The command's state at ``t_ns``.  After a reversal restarted at rest, from the
        plan from rest once it has begun: the shaft follows that plan (the motion is
        solved on it), the stored profile equals it within float noise, and a cycle
        that repeats the reversal then starts each repeat from the same numbers (and
        finds its plan remembered: dynamics.MotionMemos)."""
        return self._command_at(t_ns).state_at(t_ns)

    def _command_end(self, now: int) -> int | None:
        """Where the command ends, from the plan from rest as :meth:`_command_state`."""
        return self._command_at(now).end_ns

    def _command_at(self, t_ns: int) -> Profile:
        """The profile the command follows at ``t_ns``: the plan from rest of the last
        restarted reversal once it has begun (while ``profile`` is still the one planned
        then), else ``profile``."""
        rest = self._rest
        if rest is not None and rest[0] is self.profile and t_ns >= rest[1].origin_ns:
            return rest[1]
        return self.profile

    # -- servo on / off and the drive --------------------------------------
    @property
    def enabled(self) -> bool:
        return self._enabled

    @enabled.setter
    def enabled(self, on: bool) -> None:
        if bool(on) != self._enabled:
            self._enabled = bool(on)
            self.hold_here()

    def refresh(self) -> None:
        """The drive changed (torque limit, load, stoppers): re-solve from now."""
        self._resolve()

    # -- commands -----------------------------------------------------------
    def move(self, waypoints: Sequence[tuple[float, Limits]], *,
             start_ns: int | None = None) -> None:
        """Move through user-coordinate waypoints (merge when more than one).

        ``start_ns``: the move starts then (a command still travelling down the chain);
        only an axis at rest, or holding for a start not yet reached, can wait for it.
        """
        raw = [Waypoint(self.to_raw(t), lim) for t, lim in waypoints]
        now = self.kernel.now
        start = now
        if start_ns is not None and start_ns > now and (
                not self.moving or self.profile.origin_ns > now):
            start = start_ns
        state = self._command_state(start) if start > now else self._raw_state()
        profile = planner.plan_moves(state, raw, start, self.memos.plans)
        self.target_raw = raw[-1].target
        end = self._command_end(now)
        if (self.restart_at_rest and end is not None and start == now and not self.moving
                and len(raw) == 1 and now >= self.profile.origin_ns
                and self._current_drive() is self.motion.drive
                and stops_then_restarts(self.profile, profile)):
            # In position before the command ended (ch. 3 K55) and the new move reverses:
            # the planner runs the command on to its end, then starts from rest.  The
            # shaft follows the old command as solved until that end, and the new move
            # is solved from there, from rest (the same numbers for each repeat of a
            # cycle: docs/performance.md "Where the time goes").
            rest = planner.plan_moves(self._command_state(end), raw, end, self.memos.plans)
            self.profile = profile
            self._rest = (profile, rest)
            self.moving = True
            self._resolve(Motion.continued(self.motion, now, rest))
            return
        self._start(profile)

    def run_profile(self, profile: Profile) -> None:
        """Follow a precomputed closed-form profile in user coordinates (an axis of an
        interpolation, 4.4) with the same tracking, in-position and passing points as
        :meth:`move`.  Its origin may lie ahead (a command still on its way down the
        chain): the axis holds its position until then."""
        raw = _to_raw(profile, self.zero + self.sign * self._turn(), self.sign)
        self.target_raw = raw.final_position
        self._start(raw)

    def run(self, velocity: float, limits: Limits) -> None:
        """Continuous rotation at a signed user velocity (pps)."""
        profile = planner.plan_velocity(self._raw_state(), self.sign * velocity, limits,
                                        self.kernel.now)
        self.target_raw = float("inf") if self.sign * velocity > 0 else float("-inf")
        if velocity == 0:
            self.target_raw = profile.final_position
        self._start(profile)

    def stop(self, decel: float, scurve: int = 0, *, creep: float = 0.0,
             speed: float | None = None) -> None:
        """Decelerate to a stop; the stop point becomes the target (ch. 3 K55).

        ``creep`` and ``speed`` (of the motion being stopped) give the K51 end jump and
        the K69 jerk, as for a planned stop.
        """
        if not self.moving:
            return
        profile = planner.plan_stop(self._raw_state(), decel, self.kernel.now, scurve,
                                    creep=creep, speed=speed)
        self.target_raw = profile.final_position
        self._start(profile)

    def hold_here(self) -> None:
        """Command := the actual position, at rest (enable, free, alarm reset)."""
        here = self.raw_actual()
        self.profile = hold(here, self.kernel.now)
        self.target_raw = here
        self.moving = False
        self._resolve()

    def follow(self, user_target: float, period_ns: int = 0) -> None:
        """Move the command to a new target; the shaft follows (csp, Dx).

        Given the period of the targets' stream (csp: one target a cycle), the command
        ramps to the target at constant speed over that period, as a drive interpolates
        between the targets of a cyclic mode: a stepper has no position loop that would
        smooth a step (it would lose its steps), and a servo's loop would meet each
        step at its torque limit (docs/fidelity.md "csp between two targets").  The
        motion is then solved as far as the next target only (:class:`.dynamics.Motion`
        ``horizon_ns``).  Without a period (``Dx``, a stream of unknown period) the
        command steps to the target and the servo follows with its lag."""
        raw = self.to_raw(user_target)
        self.target_raw = raw
        now = self.kernel.now
        if period_ns > 0:
            start = self.profile.position_at(now)
            if start != raw:
                span = period_ns / 1e9
                ramp = Segment(0.0, span, start, (raw - start) / span, 0.0, 0.0)
                # one segment from 0 of the period's length: nothing to check
                profile = Profile(now, (ramp,), final_position=raw, checked=True)
                self._stream, self._stream_due = profile, now + period_ns
                self._start(profile)
                return
        self._start(hold(raw, now))

    def nudge(self, user_target: float, window: float) -> bool:
        """Shift the target of a motor at rest by no more than the in-position window,
        silently: it stays in position (analog position control, ch. 3 K38=1).
        Returns False (nothing done) when moving or when the step is larger."""
        if self.moving:
            return False
        now = self.kernel.now
        raw = self.to_raw(user_target)
        e0 = self.motion.error_at(now) + (raw - self.profile.position_at(now))
        if abs(e0) > window:
            return False
        self.profile = hold(raw, now)
        self.target_raw = raw
        self._resolve()
        return True

    def drive(self, profile: Profile) -> None:
        """Follow a profile built outside the planner (analog speed/torque control)."""
        self.target_raw = profile.final_position
        self._start(profile)

    def set_user_position(self, user: float) -> None:
        """Declare the current actual position to be ``user`` (``|2``, counter reset)."""
        self.zero = self.raw_actual() - self.sign * user
        if not self.moving:
            self.hold_here()
        else:
            self._remember()

    def place(self, raw: float) -> None:
        """Put the shaft at raw position ``raw``, at rest, counting it as user 0."""
        self._cancel()
        self.zero = float(raw)
        self.profile = hold(raw, self.kernel.now)
        self.motion = Motion(self.profile, self.kernel.now, raw, 0.0, self.servo.drive(),
                             self.memos)
        self.target_raw = float(raw)
        self.moving = False
        self._resolve()

    # -- watchers -------------------------------------------------------------
    def add_watcher(self, watcher: Watcher, index: int | None = None) -> None:
        """Watch with ``watcher`` too: last, or at ``index`` in :attr:`watchers` (the
        order in which watchers due at one instant fire)."""
        i = len(self._watchers) if index is None else max(0, min(index, len(self._watchers)))
        self._watchers.insert(i, watcher)
        self._watch_timers.insert(i, None)
        self._arm(i, self.kernel.now)

    def remove_watcher(self, watcher: Watcher) -> None:
        i = self._place_of(watcher)
        if i is None:
            return
        timer = self._watch_timers.pop(i)
        del self._watchers[i]
        if timer is not None:
            timer.cancel()

    def rearm(self, watcher: Watcher) -> None:
        """Ask ``watcher`` again for its next instant (its own state changed)."""
        i = self._place_of(watcher)
        if i is not None:
            self._arm(i, self.kernel.now)

    def _place_of(self, watcher: Watcher) -> int | None:
        for i, w in enumerate(self._watchers):
            if w is watcher:
                return i
        return None

    def _arm(self, i: int, after_ns: int) -> None:
        """Watcher ``i``'s event: cancelled, then asked again from ``after_ns``."""
        timers = self._watch_timers
        old = timers[i]
        if old is not None:
            old.cancel()
        timers[i] = self._watch(self._watchers[i], after_ns)

    def _watch(self, watcher: Watcher, after_ns: int) -> Timer | None:
        at = watcher.next_time(self, after_ns)
        if at is None:
            return None
        return self.kernel.schedule_at(at, partial(self._fire, watcher), priority=PRIO_MOTION,
                                       name=type(watcher).__name__)

    def _fire(self, watcher: Watcher) -> None:
        i = self._place_of(watcher)
        if i is not None:
            self._watch_timers[i] = None
        generation = self.generation
        watcher.fire(self)
        if generation == self.generation:
            i = self._place_of(watcher)
            if i is not None:
                self._arm(i, self.kernel.now + 1)

    # -- history (trace) ------------------------------------------------------
    def record_history(self, on: bool = True) -> None:
        """Keep every trajectory from now on so a trace can be sampled afterwards."""
        self.history = [] if on else None
        self._remember()

    def _remember(self) -> None:
        if self.history is not None:
            self.history.append((self.kernel.now, self.profile, self.motion,
                                 self.zero, self.sign))
        for listener in tuple(self.trajectory_listeners):
            listener()

    # -- internals ----------------------------------------------------------
    def _cancel(self) -> None:
        self._frontier_at = None
        for timer in self._timers:
            timer.cancel()
        self._timers.clear()
        timers = self._watch_timers
        for i, watching in enumerate(timers):
            if watching is not None:
                watching.cancel()
                timers[i] = None

    def _resolve(self, motion: Motion | None = None) -> None:
        """Re-solve the shaft motion from the actual state now (or take ``motion``,
        solved from it) and re-arm everything."""
        now = self.kernel.now
        self.servo.motion_ends(self.motion, now)
        self._cancel()
        self.generation += 1
        if motion is None:
            horizon: int | None = None
            if self._stream is self.profile and self._stream_due > now \
                    and not self.solve_in_full:
                horizon = self._stream_due
            motion = Motion(self.profile, now, self.raw_actual(), self.raw_velocity(),
                            self._current_drive(), self.memos, horizon_ns=horizon)
        self.motion = motion
        if len(self.motion.pieces) >= 2000:
            # the solver's safety net (dynamics.MAX_PIECES): a model bug, said so
            log.warning("the motion model gave up (piece limit) at virtual time %.6f s: "
                        "the shaft holds still from there; please report the script or "
                        "commands that led here", now / 1e9)
        self._remember()
        self._arm_all(now)

    def _arm_all(self, now: int) -> None:
        """Milestones and watchers on the motion from ``now``; on a motion solved in part,
        a look again where the part ends, unless a new motion comes first."""
        motion = self.motion
        if self.moving:
            self._schedule_milestones()
        frontier = motion.frontier_ns()
        if frontier is not None:
            # one event for every axis whose stream is due then (a fieldbus cycle)
            self._frontier_at = due = max(frontier, now)
            self.kernel.schedule_shared(due, self._on_frontier, priority=PRIO_HORIZON,
                                        name="motion-frontier")
        # every watcher's event was cancelled (_cancel): asked again, each in its place
        timers = self._watch_timers
        for i, watcher in enumerate(self._watchers):
            timers[i] = self._watch(watcher, now)

    def _frontier_due(self) -> None:
        if self._frontier_at == self.kernel.now:    # else a new motion came since
            self._at_frontier()

    def _at_frontier(self) -> None:
        """No new motion came by the end of the part solved (a stream stopped): solve
        the rest, and look for the milestones and alarms on it from now."""
        self._cancel()
        self.motion.complete()
        self._arm_all(self.kernel.now)

    def _current_drive(self) -> Drive:
        drive = self.servo.drive()
        if drive.enabled != self._enabled:
            from dataclasses import replace
            drive = replace(drive, enabled=self._enabled)
        return drive

    def _start(self, profile: Profile) -> None:
        self.profile = profile
        self.moving = True
        self._resolve()

    def _schedule_milestones(self) -> None:
        now = self.kernel.now
        if self.profile.passing_times:
            self._schedule_passing_points(now)
        done = self.in_position_time(now)
        if done is not None:
            self._timers.append(self.kernel.schedule_at(done, self._arrived,
                                                        priority=PRIO_MOTION,
                                                        name="in-position"))

    def _schedule_passing_points(self, now: int) -> None:
        for t_ns, index in self.profile.passing_times_ns():
            if t_ns >= now:
                self._timers.append(self.kernel.schedule_at(
                    t_ns, partial(self.servo.passing_point, index),
                    priority=PRIO_MOTION, name="passing-point"))

    def in_position_time(self, after_ns: int) -> int | None:
        """When the actual position comes within K55 of the target (``None``: not in
        this motion).

        Ch. 3 K55: "Different from motion completion signal, in-position is detected
        when the current position is within the set range against the target
        position" and "In-Position may be detected before reaching the target
        position": the command may still be on its last pulses.  Only the command's
        final approach counts (from where it stays within K55 of the target), so a
        path that passes the target earlier is not in position there."""
        window = float(self.servo.in_position_window())
        approach = self.profile.settles_ns(self.target_raw, window)
        if approach is None:
            return None
        return self.motion.within(self.target_raw, window, max(after_ns, approach))

    def _arrived(self) -> None:
        self.moving = False
        self.servo.in_position()


def wrap_user(user: float, half: float) -> float:
    """``user`` as a counter of span 2·``half`` shows it: within [-half, half)."""
    if -half <= user < half or not math.isfinite(user):
        return user
    span = 2.0 * half
    return user - math.floor((user + half) / span) * span


def _to_raw(profile: Profile, zero: float, sign: int) -> Profile:
    """``profile`` (user pulses) in raw pulses: ``raw = zero + sign * user``."""
    if zero == 0.0 and sign == 1:
        return profile
    p, v, a = profile.start_state
    segments = [Segment(s.start, s.duration, zero + sign * s.p, sign * s.v, sign * s.a,
                        sign * s.j) for s in profile.segments]
    return Profile(profile.origin_ns, segments, start_state=(zero + sign * p, sign * v, sign * a),
                   final_position=zero + sign * profile.final_position,
                   passing_times=profile.passing_times)
