"""The servo axis: the commanded trajectory, the actual position, and motion milestones.

The command is a closed-form :class:`~coolmuscle.motor.profile.Profile`; the actual
position follows it through :class:`~coolmuscle.motor.servo.Tracking`.  The axis
schedules one kernel event per milestone (in-position; merge passing points) and
re-plans from the current state when a new move, speed change or stop arrives, so a
move costs a handful of events, not a tick per millisecond.

Coordinates: the axis works in raw encoder pulses; the user coordinate is
``sign * (raw - zero)``: ``|2`` moves ``zero`` (2.1.2), reverse coordinates (K45
first digit 2/3, ch. 3 K45) flip ``sign``.

In-position (ch. 3 K55, Ux=8) is declared when the command has reached its target and
the tracking error is within K55 (docs/fidelity.md "Motion").
"""

from __future__ import annotations

import logging
from typing import Callable, Sequence

from ..sim.kernel import PRIO_MOTION, Kernel, Timer
from . import planner
from .planner import Limits, Waypoint
from .profile import Profile, Segment, hold
from .servo import DEFAULT_KP, Tracking

log = logging.getLogger(__name__)


class Axis:
    """One motor shaft under position control."""

    def __init__(self, kernel: Kernel, *, kp: float = DEFAULT_KP,
                 in_position_window: Callable[[], int] = lambda: 5,
                 on_in_position: Callable[[], None] = lambda: None,
                 on_passing_point: Callable[[int], None] = lambda index: None) -> None:
        self.kernel = kernel
        self.kp = kp
        self._window = in_position_window
        self._on_in_position = on_in_position
        self._on_passing_point = on_passing_point
        self.zero = 0.0
        self.sign = 1
        self.enabled = True
        self.profile: Profile = hold(0.0, kernel.now)
        self.tracking = Tracking(self.profile, 0.0, kp)
        self.target_raw = 0.0
        self.moving = False
        self._timers: list[Timer] = []
        #: (time_ns, profile, tracking, zero, sign) kept while a trace records.
        self.history: list[tuple[int, Profile, Tracking, float, int]] | None = None
        #: Called after every trajectory change (rotation pulses, external encoder:
        #: :class:`coolmuscle.motor.trajectory.Timeline`).
        self.trajectory_listeners: list[Callable[[], None]] = []

    # -- coordinates ------------------------------------------------------
    def to_raw(self, user: float) -> float:
        """User pulses -> raw pulses."""
        return self.zero + self.sign * user

    def to_user(self, raw: float) -> float:
        """Raw pulses -> user pulses."""
        return self.sign * (raw - self.zero)

    # -- live values (closed form at kernel.now) --------------------------
    def raw_command(self) -> float:
        return self.profile.position_at(self.kernel.now)

    def raw_actual(self) -> float:
        now = self.kernel.now
        return self.profile.position_at(now) - self.tracking.error_at(now)

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
        return self.sign * self.tracking.error_at(self.kernel.now)

    def velocity(self) -> float:
        """Actual speed, user pulses/s (?97 before unit conversion)."""
        return self.sign * self.tracking.actual_velocity_at(self.kernel.now)

    def command_velocity(self) -> float:
        return self.sign * self.profile.velocity_at(self.kernel.now)

    def command_acceleration(self) -> float:
        return self.sign * self.profile.acceleration_at(self.kernel.now)

    def _raw_state(self) -> tuple[float, float, float]:
        return self.profile.state_at(self.kernel.now)

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
        state = self.profile.state_at(start) if start > now else self._raw_state()
        profile = planner.plan_moves(state, raw, start)
        self.target_raw = raw[-1].target
        self._start(profile)

    def run_profile(self, profile: Profile) -> None:
        """Follow a precomputed closed-form profile in user coordinates (an axis of an
        interpolation, 4.4) with the same tracking, in-position and passing points as
        :meth:`move`.  Its origin may lie ahead (a command still on its way down the
        chain): the axis holds its position until then."""
        raw = _to_raw(profile, self.zero, self.sign)
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
        """Servo on, holding the actual position with no error (enable, alarm reset)."""
        self._cancel()
        here = self.raw_actual()
        self.profile = hold(here, self.kernel.now)
        self.tracking = Tracking(self.profile, 0.0, self.kp)
        self.target_raw = here
        self.moving = False
        self._remember()

    def follow(self, user_target: float) -> None:
        """Step the command to a new target; the servo follows with its lag (csp, Dx)."""
        now = self.kernel.now
        raw = self.to_raw(user_target)
        e0 = self.tracking.error_at(now) + (raw - self.profile.position_at(now))
        self._cancel()
        self.profile = hold(raw, now)
        self.tracking = Tracking(self.profile, e0, self.kp)
        self.target_raw = raw
        self.moving = True
        self._remember()
        done = now + self.tracking.settle_ns(float(self._window()))
        self._timers.append(self.kernel.schedule_at(done, self._arrived,
                                                    priority=PRIO_MOTION, name="in-position"))

    def nudge(self, user_target: float, window: float) -> bool:
        """Shift the target of a motor at rest by no more than the in-position window,
        silently: it stays in position (analog position control, ch. 3 K38=1).
        Returns False (nothing done) when moving or when the step is larger."""
        if self.moving:
            return False
        now = self.kernel.now
        raw = self.to_raw(user_target)
        e0 = self.tracking.error_at(now) + (raw - self.profile.position_at(now))
        if abs(e0) > window:
            return False
        self._cancel()
        self.profile = hold(raw, now)
        self.tracking = Tracking(self.profile, e0, self.kp)
        self.target_raw = raw
        self._remember()
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

    # -- history (trace) ------------------------------------------------------
    def record_history(self, on: bool = True) -> None:
        """Keep every trajectory from now on so a trace can be sampled afterwards."""
        self.history = [] if on else None
        self._remember()

    def _remember(self) -> None:
        if self.history is not None:
            self.history.append((self.kernel.now, self.profile, self.tracking,
                                 self.zero, self.sign))
        for listener in tuple(self.trajectory_listeners):
            listener()

    # -- internals ----------------------------------------------------------
    def _cancel(self) -> None:
        for timer in self._timers:
            timer.cancel()
        self._timers.clear()

    def _start(self, profile: Profile) -> None:
        now = self.kernel.now
        e0 = self.tracking.error_at(now)
        self._cancel()
        self.profile = profile
        self.tracking = Tracking(profile, e0, self.kp)
        self.moving = True
        self._remember()
        for t_ns, index in profile.passing_times_ns():
            if t_ns >= now:
                self._timers.append(self.kernel.schedule_at(
                    t_ns, lambda i=index: self._on_passing_point(i),
                    priority=PRIO_MOTION, name="passing-point"))
        end = profile.end_ns
        if end is None:
            return
        done = end + self.tracking.settle_ns(float(self._window()))
        self._timers.append(self.kernel.schedule_at(done, self._arrived,
                                                    priority=PRIO_MOTION, name="in-position"))

    def _arrived(self) -> None:
        self.moving = False
        self._on_in_position()


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
