"""Closed-form motion profiles: position as a piecewise cubic of time.

This module owns :class:`Segment`, :class:`Profile` and :func:`hold`.  A profile is
what the planner (:mod:`coolmuscle.motor.motion.planner`) produces and what the axis
executes: a chain of constant-jerk segments starting at the kernel instant
``origin_ns``.  Everything is evaluated in closed form at any instant, and the
instants the model cares about (a position reached, a speed fallen below a value)
are solved per segment, never polled (docs/architecture.md rule 2).

Conventions (docs/fidelity.md "Motion"):

* Segment times are float seconds relative to ``origin_ns``; queries take integer
  kernel nanoseconds.
* Position is continuous everywhere.  Velocity may jump only where the planner puts
  a documented creep-speed jump (ch. 3 K51); acceleration may jump at segment
  boundaries of a trapezoidal profile (K69=0).
* Before ``origin_ns`` a profile reports its start state; from ``end_ns`` on it
  reports the final position at rest.  Only the last segment may be endless
  (continuous rotation, 2.1.1 ``P=1000000000``); it then cruises at constant speed.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final

from ...sim.kernel import NS_PER_S, seconds

State = tuple[float, float, float]

_ITERATIONS: Final = 200


@dataclass(init=False, unsafe_hash=True, slots=True)
class Segment:
    """A constant-jerk piece: p(τ) = p + vτ + aτ²/2 + jτ³/6 for 0 <= τ <= duration.

    ``start`` is in seconds from the profile origin; ``duration`` may be ``math.inf``
    only for the last segment of continuous rotation (then ``a == j == 0``).
    Immutable by convention (nothing assigns its fields).
    """

    start: float
    duration: float
    p: float
    v: float
    a: float
    j: float

    def __init__(self, start: float, duration: float, p: float, v: float, a: float,
                 j: float) -> None:
        # written out: built on the hot path (docs/architecture.md "Fast code")
        self.start = start
        self.duration = duration
        self.p = p
        self.v = v
        self.a = a
        self.j = j

    @property
    def end(self) -> float:
        """End time (s from the origin)."""
        return self.start + self.duration

    def position(self, tau: float) -> float:
        """Position τ seconds into the segment."""
        return self.p + tau * (self.v + tau * (self.a / 2.0 + tau * self.j / 6.0))

    def velocity(self, tau: float) -> float:
        """Velocity τ seconds into the segment."""
        return self.v + tau * (self.a + tau * self.j / 2.0)

    def acceleration(self, tau: float) -> float:
        """Acceleration τ seconds into the segment."""
        return self.a + tau * self.j

    def state(self, tau: float) -> State:
        """(position, velocity, acceleration) τ seconds into the segment."""
        return self.position(tau), self.velocity(tau), self.acceleration(tau)

    def end_state(self) -> State:
        """The state at the end of a finite segment."""
        return self.state(self.duration)


class Profile:
    """A commanded motion: segments after ``origin_ns``, queried at kernel instants."""

    __slots__ = ("origin_ns", "segments", "start_state", "final_position", "duration",
                 "end_ns", "_starts", "_passing", "_max_speed")

    def __init__(self, origin_ns: int, segments: Sequence[Segment], *,
                 start_state: State | None = None, final_position: float | None = None,
                 passing_times: Iterable[tuple[float, int]] = (),
                 checked: bool = False) -> None:
        """Build a profile; ``passing_times`` are (seconds from origin, waypoint index).
        ``checked``: the segments are a plan's or a profile's, checked already."""
        self.origin_ns = int(origin_ns)
        self.segments: tuple[Segment, ...] = tuple(segments)
        if not checked:
            _check_chain(self.segments)
        last = self.segments[-1] if self.segments else None
        if start_state is None:
            start_state = ((self.segments[0].p, self.segments[0].v, self.segments[0].a)
                           if last else (final_position or 0.0, 0.0, 0.0))
        self.start_state: State = start_state
        self.duration: float = last.end if last else 0.0
        if last is not None and math.isinf(last.duration):
            self.end_ns: int | None = None
            self.final_position: float = math.copysign(math.inf, last.v)
        else:
            self.end_ns = self.origin_ns + seconds(self.duration)
            if final_position is None:
                final_position = last.end_state()[0] if last else start_state[0]
            self.final_position = float(final_position)
        self._starts = [s.start for s in self.segments]
        self._passing = tuple(passing_times)
        self._max_speed: float | None = None

    def __repr__(self) -> str:
        return (f"Profile(origin_ns={self.origin_ns}, segments={len(self.segments)}, "
                f"duration={self.duration!r}, final={self.final_position!r})")

    # -- evaluation --------------------------------------------------------
    def _locate(self, t_ns: int) -> tuple[Segment, float] | None:
        """The segment and local time at ``t_ns``; ``None`` before origin or after end."""
        if t_ns < self.origin_ns or (self.end_ns is not None and t_ns >= self.end_ns):
            return None
        rel = (t_ns - self.origin_ns) / NS_PER_S
        seg = self.segments[bisect_right(self._starts, rel) - 1]
        return seg, min(rel - seg.start, seg.duration)

    def _outside(self, t_ns: int) -> State:
        if t_ns < self.origin_ns:
            return self.start_state
        return self.final_position, 0.0, 0.0

    def position_at(self, t_ns: int) -> float:
        """Commanded position (pulses) at kernel time ``t_ns``."""
        found = self._locate(t_ns)
        if found is None:
            return self._outside(t_ns)[0]
        seg, tau = found
        return seg.position(tau)

    def velocity_at(self, t_ns: int) -> float:
        """Commanded velocity (pulses/s) at ``t_ns``."""
        found = self._locate(t_ns)
        if found is None:
            return self._outside(t_ns)[1]
        seg, tau = found
        return seg.velocity(tau)

    def acceleration_at(self, t_ns: int) -> float:
        """Commanded acceleration (pulses/s²) at ``t_ns``."""
        found = self._locate(t_ns)
        if found is None:
            return self._outside(t_ns)[2]
        seg, tau = found
        return seg.acceleration(tau)

    def state_at(self, t_ns: int) -> State:
        """(position, velocity, acceleration) at ``t_ns``."""
        found = self._locate(t_ns)
        if found is None:
            return self._outside(t_ns)
        seg, tau = found
        return seg.state(tau)

    @property
    def passing_times(self) -> tuple[tuple[float, int], ...]:
        """(seconds from the origin, waypoint index) of each merge passing point."""
        return self._passing

    def passing_times_ns(self) -> list[tuple[int, int]]:
        """(kernel time, waypoint index) of each merge passing point (K34=6, K73)."""
        return [(self.origin_ns + seconds(t), i) for t, i in self._passing]

    def max_speed(self) -> float:
        """The largest |velocity| anywhere in the profile (pulses/s)."""
        if self._max_speed is None:
            best = abs(self.start_state[1])
            for seg in self.segments:
                best = max(best, abs(seg.v))
                if math.isinf(seg.duration):
                    continue
                best = max(best, abs(seg.velocity(seg.duration)))
                if seg.j != 0.0 and 0.0 < -seg.a / seg.j < seg.duration:
                    best = max(best, abs(seg.velocity(-seg.a / seg.j)))
            self._max_speed = best
        return self._max_speed

    # -- solved instants ---------------------------------------------------
    def _to_ns(self, rel: float, after_ns: int) -> int:
        return max(after_ns, self.origin_ns + seconds(rel))

    def _segments_from(self, after_ns: int) -> Iterable[tuple[Segment, float]]:
        rel = (after_ns - self.origin_ns) / NS_PER_S
        first = max(0, bisect_right(self._starts, rel) - 1)
        for seg in self.segments[first:]:
            yield seg, min(max(0.0, rel - seg.start), seg.duration)

    def first_crossing(self, x: float, after_ns: int) -> int | None:
        """First kernel time >= ``after_ns`` at which the position reaches ``x``.

        Solved per segment on monotonic pieces (roots of the velocity quadratic) by
        safeguarded Newton; rounded to the nearest nanosecond.  ``None`` if never.
        """
        tol = 1e-9 * max(1.0, abs(x))
        if after_ns < self.origin_ns:
            if abs(self.start_state[0] - x) <= tol:
                return after_ns
            after_ns = self.origin_ns
        if self.end_ns is None or after_ns < self.end_ns:
            for seg, tau0 in self._segments_from(after_ns):
                tau = _segment_crossing(seg, x, tau0, tol)
                if tau is not None:
                    return self._to_ns(seg.start + tau, after_ns)
        if self.end_ns is not None and abs(self.final_position - x) <= tol:
            return max(after_ns, self.end_ns)
        return None

    def settles_ns(self, center: float, window: float) -> int | None:
        """The instant from which the command stays within ``window`` of ``center`` to
        its end (ch. 3 K55: the approach to the target); ``None`` for an endless profile.

        Walked backward over monotonic pieces, so a path that passes the target earlier
        (a full circle, a merge through it) counts only its final approach."""
        if self.end_ns is None:
            return None
        if abs(self.final_position - center) > window:
            return self.end_ns
        segments = self.segments
        for s in range(len(segments) - 1, -1, -1):        # by index: no iterator object
            seg = segments[s]
            turns = _velocity_roots(seg, 0.0, seg.duration)
            hi = seg.duration
            for i in range(len(turns), -1, -1):           # its monotonic parts, last first
                lo = turns[i - 1] if i > 0 else 0.0
                off = seg.position(lo) - center
                if abs(off) <= window:
                    hi = lo
                    continue
                edge = center + math.copysign(window, off)
                tau = _solve_monotone(seg, edge, lo, hi, seg.position(lo) - edge)
                return self.origin_ns + seconds(seg.start + tau)
        return self.origin_ns

    def time_speed_below(self, speed: float, after_ns: int) -> int | None:
        """First kernel time >= ``after_ns`` at which |velocity| <= ``speed``."""
        if after_ns < self.origin_ns:
            if abs(self.start_state[1]) <= speed:
                return after_ns
            after_ns = self.origin_ns
        if self.end_ns is None or after_ns < self.end_ns:
            for seg, tau0 in self._segments_from(after_ns):
                tau = _segment_slow(seg, speed, tau0)
                if tau is not None:
                    return self._to_ns(seg.start + tau, after_ns)
        if self.end_ns is None or speed < 0.0:
            return None
        return max(after_ns, self.end_ns)


def stops_then_restarts(old: Profile, new: Profile) -> bool:
    """Whether ``new``, planned at its origin from ``old``'s command state there, runs
    the rest of ``old`` to its end at rest on ``old``'s final position, and only then
    starts again (a reversal: the planner stops, then starts, and never passes
    through zero speed).  Then ``new`` is ``old`` followed by a plan from rest at
    ``old``'s end, within float noise (:meth:`Axis.move` starts it there)."""
    if old.end_ns is None or new.end_ns is None or old.end_ns <= new.origin_ns:
        return False
    base = (new.origin_ns - old.origin_ns) / NS_PER_S        # new's origin in old's time
    rest = [seg for seg in old.segments if seg.end > base]
    if not rest or len(new.segments) <= len(rest):
        return False
    for was, will in zip(rest, new.segments):
        at = will.start + base - was.start                   # will's start in was's time
        if not (_near(was.end - base, will.end, 1e-9) and _near(was.j, will.j, 1e-9)
                and _near(was.acceleration(at), will.a, 1e-9)):
            return False
    restart = new.segments[len(rest)]
    return (_near(restart.start, old.duration - base, 1e-9) and abs(restart.v) <= 1e-6
            and _near(restart.p, old.final_position, 1e-9))


def _near(a: float, b: float, tol: float) -> bool:
    # max(1.0, abs(a), abs(b)) as the builtin folds it, left to right: compiled, a max()
    # of two floats is a comparison, of three a call of the builtin (5 a move).
    return abs(a - b) <= tol * max(max(1.0, abs(a)), abs(b))


def hold(position: float, origin_ns: int) -> Profile:
    """A standstill at ``position`` from ``origin_ns`` on (no segments)."""
    return Profile(origin_ns, (), start_state=(float(position), 0.0, 0.0),
                   final_position=float(position))


# -- helpers ---------------------------------------------------------------
def _check_chain(segments: Sequence[Segment]) -> None:
    """Segments must follow each other in time; only the last may be endless."""
    t = 0.0
    for i, seg in enumerate(segments):
        if not seg.duration > 0.0:
            raise ValueError(f"segment {i} has duration {seg.duration!r}")
        if abs(seg.start - t) > 1e-9 * max(1.0, abs(t)):
            raise ValueError(f"segment {i} starts at {seg.start!r}, expected {t!r}")
        if math.isinf(seg.duration) and (i != len(segments) - 1 or seg.a or seg.j):
            raise ValueError("only a last constant-speed segment may be endless")
        t = seg.end


def _quadratic_roots(c2: float, c1: float, c0: float) -> list[float]:
    """Real roots of c2 x² + c1 x + c0 (numerically stable), ascending."""
    if c2 == 0.0:
        return [] if c1 == 0.0 else [-c0 / c1]
    disc = c1 * c1 - 4.0 * c2 * c0
    if disc < 0.0:
        return []
    q = -0.5 * (c1 + math.copysign(math.sqrt(disc), c1))
    roots = [q / c2] if q == 0.0 else [q / c2, c0 / q]
    return sorted(roots)


def _velocity_roots(seg: Segment, lo: float, hi: float) -> tuple[float, ...]:
    """Instants in (lo, hi) where the segment's velocity is zero, ascending."""
    if seg.j == 0.0 and seg.a == 0.0:       # constant speed: none (_quadratic_roots too)
        return ()
    return tuple([r for r in _quadratic_roots(seg.j / 2.0, seg.a, seg.v) if lo < r < hi])


def _segment_crossing(seg: Segment, x: float, tau0: float, tol: float) -> float | None:
    """Smallest τ in [tau0, duration] with p(τ) = x, or ``None``."""
    if math.isinf(seg.duration):
        f0 = seg.position(tau0) - x
        if abs(f0) <= tol:
            return tau0
        if seg.v == 0.0 or (f0 > 0.0) == (seg.v > 0.0):
            return None
        return tau0 - f0 / seg.v
    cuts = [tau0, *_velocity_roots(seg, tau0, seg.duration), seg.duration]
    for lo, hi in zip(cuts, cuts[1:]):
        flo, fhi = seg.position(lo) - x, seg.position(hi) - x
        if abs(flo) <= tol:
            return lo
        if (flo < 0.0) != (fhi < 0.0) and fhi != 0.0:
            return _solve_monotone(seg, x, lo, hi, flo)
        if abs(fhi) <= tol:  # touches x at a turning point (or at the end)
            return hi
    return None


def _solve_monotone(seg: Segment, x: float, lo: float, hi: float, flo: float) -> float:
    """Root of p(τ) = x on [lo, hi] where p is monotonic: safeguarded Newton."""
    t = 0.5 * (lo + hi)
    for _ in range(_ITERATIONS):
        f = seg.position(t) - x
        if f == 0.0:
            return t
        if (f < 0.0) == (flo < 0.0):
            lo, flo = t, f
        else:
            hi = t
        if hi - lo <= 1e-15 * max(1.0, hi):
            break
        d = seg.velocity(t)
        step = t - f / d if d != 0.0 else lo - 1.0
        t = step if lo < step < hi else 0.5 * (lo + hi)
    return t if abs(seg.position(t) - x) <= abs(seg.position(hi) - x) else hi


def _segment_slow(seg: Segment, speed: float, tau0: float) -> float | None:
    """Smallest τ in [tau0, duration] with |v(τ)| <= speed, or ``None``."""
    if abs(seg.velocity(tau0)) <= speed:
        return tau0
    if speed < 0.0:
        return None
    hits = [r for target in (speed, -speed)
            for r in _quadratic_roots(seg.j / 2.0, seg.a, seg.v - target)
            if tau0 < r <= seg.duration]
    return min(hits) if hits else None
