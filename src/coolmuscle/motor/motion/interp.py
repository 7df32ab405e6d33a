"""Circular and linear interpolation of two adjacent motors (cml-users-guide.txt 4.4, 2.1.2 "@").

Geometry: the start point is the current position of the X motor (the lower ID) and
the Y motor; the end point is their P data.  With ``R`` the path is an arc of that
radius (equal radii: a circle; different radii: an oval whose semi-axes are the two
radii), the major arc for a positive radius and the minor arc for a negative radius
or the ``-`` modifier (4.4.1); with ``N`` the arc is centred on the N data (4.4.2; when the
end is not as far from the centre as the start, the radius changes evenly with the angle, a
spiral arc);
``R`` = 0 draws a straight line (4.4.3).  ``+`` turns CW, ``-`` CCW.

Timing: the arc length ``s(t)`` is planned as a one-dimensional move with the
planner (S is the speed along the path, A its acceleration; merge motion through
consecutive paths keeps moving at the junction), then each axis's position
``x(s(t))`` becomes a chain of cubic Hermite pieces in time, so every axis still
follows a closed-form piecewise-polynomial Profile.  Lines are exact; arc pieces are
short enough that the curve is followed within a small fraction of a pulse.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Sequence
from dataclasses import dataclass

from .planner import Limits, Waypoint, plan_moves
from .profile import Profile, Segment

Point = tuple[float, float]

#: Largest distance (pulses) between a cubic piece and the true path at its check points.
MAX_ERROR = 0.05
#: Largest relative error of the axis velocities of a piece anywhere on it, so the
#: speed along the path stays at S (4.4 "synthetic speed by 2 axes").  The check
#: points hold half of it: between them a cubic's velocity error can grow a little
#: (an oval of axis ratio 17 with S-curves ran at S x (1 + 1.014e-4) when the check
#: points held all of it; tests/test_interp_geometry.py).
MAX_SPEED_ERROR = 1e-4
_CHECK_SPEED_ERROR = MAX_SPEED_ERROR / 2
#: Largest difference between the arc length of a table step (Gauss–Legendre, 5 points)
#: and the sum of its halves, relative to the step's angle times the slowest speed on it.
#: The speed the table implies then stays within 3e-7 of the true speed (ovals of axis
#: ratio up to 1000, any start angle), far inside MAX_SPEED_ERROR.  Circles and ovals up
#: to an axis ratio of about 8 meet it with the steps of π/32 and are not split.
TABLE_ERROR = 1e-8
#: Most halvings of a table step (π/32 / 2^40 ≈ 1e-13 rad: a few hundred float steps of
#: an angle, below the tip of any oval of integer radii up to 1e9).
TABLE_DEPTH = 40
#: Shortest piece (s): the kernel's clock has nanoseconds, pieces stop splitting here.
MIN_PIECE = 1e-6
#: A centre (4.4.2) whose distances to the start and the end differ by at most this
#: much (pulses) draws a circular arc; a larger difference draws a spiral arc.
RADIUS_TOLERANCE = 0.5
_GAUSS = ((-0.906179845938664, 0.236926885056189), (-0.538469310105683, 0.478628670499366),
          (0.0, 0.568888888888889), (0.538469310105683, 0.478628670499366),
          (0.906179845938664, 0.236926885056189))


class PathError(ValueError):
    """An interpolation that cannot be drawn (documented in docs/fidelity.md)."""


class Line:
    """A straight segment from ``start`` to ``end`` (4.4.3)."""

    def __init__(self, start: Point, end: Point) -> None:
        self.start, self.end = start, end
        self.length = math.dist(start, end)

    def point(self, s: float) -> Point:
        if self.length == 0 or s >= self.length:
            return self.end
        f = max(s / self.length, 0.0)
        return (self.start[0] + f * (self.end[0] - self.start[0]),
                self.start[1] + f * (self.end[1] - self.start[1]))

    def tangent(self, s: float) -> Point:
        if self.length == 0:
            return (0.0, 0.0)
        return ((self.end[0] - self.start[0]) / self.length,
                (self.end[1] - self.start[1]) / self.length)


class Arc:
    """An arc of an axis-aligned ellipse (a circle when ``rx == ry``).

    ``theta0`` is the start angle, ``sweep`` the signed angle travelled (negative =
    CW).  Points: ``center + (rx cos θ, ry sin θ)``.  Arc length is tabulated with
    Gauss–Legendre quadrature (steps of at most π/32, halved where the rule is not
    accurate: at the tips of flat ovals) and inverted by Newton's method.
    """

    def __init__(self, center: Point, rx: float, ry: float, theta0: float, sweep: float,
                 end: Point | None = None) -> None:
        self.center, self.rx, self.ry = center, abs(rx), abs(ry)
        self.theta0, self.sweep = theta0, sweep
        self.exact_end = end
        n = max(8, int(abs(sweep) / (math.pi / 32)) + 1)
        grid = [theta0 + sweep * i / n for i in range(n + 1)]
        self._thetas = [theta0]
        self._lengths = [0.0]
        for a, b in zip(grid, grid[1:]):
            for step_end, length in self._table(a, b, 0):
                self._thetas.append(step_end)
                self._lengths.append(self._lengths[-1] + length)
        self.length = self._lengths[-1]

    def _speed(self, theta: float) -> float:
        return math.hypot(self.rx * math.sin(theta), self.ry * math.cos(theta))

    def _length(self, a: float, b: float) -> float:
        half, mid = (b - a) / 2, (a + b) / 2
        return abs(half) * sum(w * self._speed(mid + half * x) for x, w in _GAUSS)

    def _table(self, a: float, b: float, depth: int) -> list[tuple[float, float]]:
        """Ends and lengths of the table steps over [a, b]: halved while the rule on the
        whole step and on its halves disagree by more than :data:`TABLE_ERROR`.

        At the tips of a flat oval |dP/dθ| dips to the short radius over an angle about
        the axis ratio (ry/rx); on a wider step the rule, inverted by :meth:`theta`,
        puts the points off the path speed (5.4e-5 at an axis ratio of 25), which no
        cubic piece can meet (docs/fidelity.md, "Interpolation").
        """
        whole = self._length(a, b)
        if depth < TABLE_DEPTH:
            mid = (a + b) / 2
            halves = self._length(a, mid) + self._length(mid, b)
            slowest = min(self._speed(a), self._speed(mid), self._speed(b))
            if abs(halves - whole) > TABLE_ERROR * abs(b - a) * slowest:
                return self._table(a, mid, depth + 1) + self._table(mid, b, depth + 1)
        return [(b, whole)]

    def theta(self, s: float) -> float:
        """Angle at arc length ``s`` from the start: Newton's method from the start of
        its table step, kept inside the step (a step that would leave it halves the
        bracket instead: from the tip of a flat oval, where the speed is tiny, a bare
        Newton step flies off by thousands of radians)."""
        s = min(max(s, 0.0), self.length)
        i = min(max(bisect_right(self._lengths, s) - 1, 0), len(self._thetas) - 2)
        a = self._thetas[i]
        lo, hi = sorted((a, self._thetas[i + 1]))
        base = self._lengths[i]
        direction = 1.0 if self.sweep >= 0 else -1.0
        theta = a
        for _ in range(30):
            err = base + self._length(a, theta) - s
            if (err < 0) == (direction > 0):
                lo = theta      # short of s going up, or past it going down
            else:
                hi = theta
            speed = self._speed(theta) or 1e-12
            step = err / speed
            following = theta - direction * step
            if not lo <= following <= hi:
                following = (lo + hi) / 2
                step = following - theta
            theta = following
            if abs(step) < 1e-13:
                break
        return theta

    def point(self, s: float) -> Point:
        if self.exact_end is not None and s >= self.length:
            return self.exact_end
        t = self.theta(s)
        return (self.center[0] + self.rx * math.cos(t), self.center[1] + self.ry * math.sin(t))

    def tangent(self, s: float) -> Point:
        t = self.theta(s)
        dx, dy = -self.rx * math.sin(t), self.ry * math.cos(t)
        norm = math.hypot(dx, dy) or 1.0
        sign = 1.0 if self.sweep >= 0 else -1.0
        return (sign * dx / norm, sign * dy / norm)


class SpiralArc(Arc):
    """An arc round ``center`` whose radius goes evenly from ``r0`` to ``r1`` with the
    angle: a centre (4.4.2) not equally far from the start and the end still starts at
    the start and ends exactly at the end (docs/fidelity.md "Daisy chain")."""

    def __init__(self, center: Point, r0: float, r1: float, theta0: float, sweep: float,
                 end: Point | None = None) -> None:
        self.r0, self.growth = r0, (r1 - r0) / sweep if sweep else 0.0
        super().__init__(center, r0, r0, theta0, sweep, end)

    def _radius(self, theta: float) -> float:
        return self.r0 + self.growth * (theta - self.theta0)

    def _speed(self, theta: float) -> float:
        return math.hypot(self._radius(theta), self.growth)

    def point(self, s: float) -> Point:
        if self.exact_end is not None and s >= self.length:
            return self.exact_end
        t = self.theta(s)
        r = self._radius(t)
        return (self.center[0] + r * math.cos(t), self.center[1] + r * math.sin(t))

    def tangent(self, s: float) -> Point:
        t = self.theta(s)
        r = self._radius(t)
        dx = self.growth * math.cos(t) - r * math.sin(t)
        dy = self.growth * math.sin(t) + r * math.cos(t)
        norm = math.hypot(dx, dy) or 1.0
        sign = 1.0 if self.sweep >= 0 else -1.0
        return (sign * dx / norm, sign * dy / norm)


class SubPath:
    """The rest of ``path`` from arc length ``s0`` on (a path resumed after a pause)."""

    def __init__(self, path: Line | Arc | SubPath, s0: float) -> None:
        self.path, self.s0 = path, min(max(s0, 0.0), path.length)
        self.length: float = path.length - self.s0

    def point(self, s: float) -> Point:
        return self.path.point(self.s0 + min(max(s, 0.0), self.length))

    def tangent(self, s: float) -> Point:
        return self.path.tangent(self.s0 + min(max(s, 0.0), self.length))


Path = Line | Arc | SubPath


def _sweep(theta0: float, theta1: float, cw: bool, full_if_equal: bool) -> float:
    d = (theta1 - theta0) % (2 * math.pi)
    if cw:
        d = d - 2 * math.pi if d > 0 else d
    if abs(d) < 1e-12 and full_if_equal:
        d = -2 * math.pi if cw else 2 * math.pi
    return d


def arc_from_radius(start: Point, end: Point, rx: float, ry: float, *, minor: bool,
                    cw: bool) -> Path:
    """4.4.1: start, end and radius; the major arc unless ``minor``; R=0 is a line."""
    if rx == 0 or ry == 0:
        return Line(start, end)
    rx, ry = abs(rx), abs(ry)
    # scale Y so the oval becomes a circle of radius rx, solve, scale back
    k = rx / ry
    a = (start[0], start[1] * k)
    b = (end[0], end[1] * k)
    chord = math.dist(a, b)
    if chord == 0:
        raise PathError("an arc by radius needs different start and end points")
    r = max(rx, chord / 2)
    mid = ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)
    h = math.sqrt(max(r * r - (chord / 2) ** 2, 0.0))
    ux, uy = (b[0] - a[0]) / chord, (b[1] - a[1]) / chord
    candidates = []
    for side in (1.0, -1.0):
        c = (mid[0] - side * uy * h, mid[1] + side * ux * h)
        t0 = math.atan2(a[1] - c[1], a[0] - c[0])
        t1 = math.atan2(b[1] - c[1], b[0] - c[0])
        candidates.append((c, t0, _sweep(t0, t1, cw, False)))
    # the minor arc sweeps at most half a turn; a half circle (chord = 2R) is both
    c, t0, sweep = min(candidates, key=lambda cand: abs(cand[2]) if minor else -abs(cand[2]))
    return Arc((c[0], c[1] / k), r, r / k, t0, sweep, end)


def arc_from_center(start: Point, end: Point, center: Point, *, cw: bool) -> Path:
    """4.4.2: start, end and centre (start == end: a full circle).

    The radius is the start's distance from the centre; when the end is farther or
    nearer by more than :data:`RADIUS_TOLERANCE` the radius changes evenly with the
    angle (:class:`SpiralArc`), so the path still ends exactly at the end.
    """
    r = math.dist(start, center)
    r_end = math.dist(end, center)
    if r == 0 or r_end == 0:
        raise PathError("the centre is the start or the end point")
    t0 = math.atan2(start[1] - center[1], start[0] - center[0])
    t1 = math.atan2(end[1] - center[1], end[0] - center[0])
    sweep = _sweep(t0, t1, cw, math.dist(start, end) < 0.5)
    if sweep == 0.0:
        return Line(start, end)        # the end lies straight out from the centre
    if abs(r_end - r) <= RADIUS_TOLERANCE:
        return Arc(center, r, r, t0, sweep, end)
    return SpiralArc(center, r, r_end, t0, sweep, end)


@dataclass(frozen=True)
class Leg:
    """One interpolated path with the limits (speed along the path) it runs at."""

    path: Path
    limits: Limits


def _hermite(t0: float, h: float, p0: float, v0: float, p1: float, v1: float) -> Segment:
    a = (6 * (p1 - p0) - h * (4 * v0 + 2 * v1)) / (h * h)
    j = (12 * (p0 - p1) + 6 * h * (v0 + v1)) / (h * h * h)
    return Segment(t0, h, p0, v0, a, j)


def _knots(s_profile: Profile, starts: list[float]) -> list[float]:
    """Where pieces must break: planner segment bounds and the junctions of legs."""
    times = {0.0}
    for seg in s_profile.segments:
        times.update((seg.start, seg.end))
    origin = s_profile.origin_ns
    for s0 in starts[1:]:
        hit = s_profile.first_crossing(s0, origin)
        if hit is not None:
            times.add((hit - origin) / 1e9)
    end = s_profile.duration
    return sorted(t for t in times if 0 <= t <= end)


class _Sampler:
    """Exact axis positions and velocities along the planned path at any time."""

    def __init__(self, s_profile: Profile, legs: Sequence[Leg], starts: list[float],
                 total: float) -> None:
        self.s_profile, self.legs, self.starts, self.total = s_profile, legs, starts, total
        self.end_time = s_profile.duration
        self.s_end = min(max(s_profile.final_position, 0.0), total)
        segments = s_profile.segments
        self.end_speed = segments[-1].end_state()[1] if segments else 0.0

    def locate(self, s: float, at_end: bool = False) -> tuple[Path, float]:
        """The leg holding arc length ``s`` and the length along it."""
        i = max(bisect_right(self.starts, s) - 1, 0)
        if i > 0 and s == self.starts[i] and not at_end:
            i -= 1          # a junction belongs to the leg that ends there
        return self.legs[i].path, s - self.starts[i]

    def state(self, t: float) -> tuple[float, float, float, float]:
        """(x, y, vx, vy) at ``t`` seconds from the origin."""
        if t >= self.end_time:
            # the left limit: a creep-speed stop (K51) jumps to 0 only after the end
            s, v = self.s_end, self.end_speed
        else:
            s, v, _ = self.s_profile.state_at(self.s_profile.origin_ns + round(t * 1e9))
            s = min(max(s, 0.0), self.total)
        path, local = self.locate(s)
        (x, y), (tx, ty) = path.point(local), path.tangent(local)
        return x, y, tx * v, ty * v

    def end_point(self) -> Point:
        """Where the path profile comes to rest: the exact end of a leg when it gets there."""
        if self.s_end >= self.total - 1e-9 * max(1.0, self.total):
            last = self.legs[-1].path       # the sum of the legs' lengths may round
            return last.point(last.length)
        path, local = self.locate(self.s_end)
        return path.point(path.length if local >= path.length else local)


def _pieces(sampler: _Sampler, t0: float, t1: float, depth: int = 0) -> list[tuple[float, float]]:
    """Split [t0, t1] until each cubic Hermite piece is within MAX_ERROR of the path
    and _CHECK_SPEED_ERROR of its speed (not below MIN_PIECE, nor where the clock's
    float cannot halve the piece: a path lasting years)."""
    h = t1 - t0
    a, b = sampler.state(t0), sampler.state(t1)
    x_seg = _hermite(t0, h, a[0], a[2], b[0], b[2])
    y_seg = _hermite(t0, h, a[1], a[3], b[1], b[3])
    mid = t0 + h / 2
    if depth < 24 and h > MIN_PIECE and t0 < mid < t1:
        for f in (0.25, 0.5, 0.75):
            x, y, vx, vy = sampler.state(t0 + f * h)
            tau = f * h
            if (math.hypot(x_seg.position(tau) - x, y_seg.position(tau) - y) > MAX_ERROR
                    or math.hypot(x_seg.velocity(tau) - vx, y_seg.velocity(tau) - vy)
                    > _CHECK_SPEED_ERROR * max(math.hypot(vx, vy), 1.0)):
                return _pieces(sampler, t0, mid, depth + 1) + _pieces(sampler, mid, t1, depth + 1)
    return [(t0, t1)]


def leg_starts(legs: Sequence[Leg]) -> tuple[list[float], float]:
    """Arc length at the start of each leg, and the total length."""
    starts, total = [], 0.0
    for leg in legs:
        starts.append(total)
        total += leg.path.length
    return starts, total


def follow_path(legs: Sequence[Leg], s_profile: Profile) -> tuple[Profile, Profile]:
    """X and Y profiles that follow ``legs`` as the path length ``s_profile`` says.

    ``s_profile`` is any closed-form plan of the arc length (a full path from 0, or a
    stop or a resumption part way along); the axis profiles are cubic Hermite pieces
    within :data:`MAX_ERROR` of the path, and end exactly at the point where ``s`` rests.
    """
    starts, total = leg_starts(legs)
    sampler = _Sampler(s_profile, legs, starts, total)
    origin = s_profile.origin_ns
    end = sampler.end_point()
    if not s_profile.segments:
        x0, y0, _, _ = sampler.state(0.0)
        return (Profile(origin, (), start_state=(x0, 0.0, 0.0), final_position=end[0]),
                Profile(origin, (), start_state=(y0, 0.0, 0.0), final_position=end[1]))
    x_segs: list[Segment] = []
    y_segs: list[Segment] = []
    times = _knots(s_profile, starts)
    for t0, t1 in zip(times, times[1:]):
        if t1 - t0 <= 0:
            continue
        for p0, p1 in _pieces(sampler, t0, t1):
            a, b = sampler.state(p0), sampler.state(p1)
            x_segs.append(_hermite(p0, p1 - p0, a[0], a[2], b[0], b[2]))
            y_segs.append(_hermite(p0, p1 - p0, a[1], a[3], b[1], b[3]))
    passing = s_profile.passing_times
    x_profile = Profile(origin, x_segs, final_position=end[0], passing_times=passing)
    y_profile = Profile(origin, y_segs, final_position=end[1], passing_times=passing)
    return x_profile, y_profile


def plan_path(legs: Sequence[Leg], start_speed: float, origin_ns: int) -> Profile:
    """The path length ``s(t)`` from 0 through every leg, merged at the junctions
    (4.4 "CM2 can operate merge motion, during even at the interpolation")."""
    starts, total = leg_starts(legs)
    if total == 0:
        raise PathError("the path has no length")
    waypoints = [Waypoint(s0 + leg.path.length, leg.limits) for s0, leg in zip(starts, legs)]
    return plan_moves((0.0, start_speed, 0.0), waypoints, origin_ns)


def plan_interpolation(start: Point, start_speed: float, legs: Sequence[Leg],
                       origin_ns: int) -> tuple[Profile, Profile, Profile]:
    """Profiles of X, Y and of the path length ``s`` for ``legs`` travelled in turn.

    ``start_speed`` is the path speed at the start (merge continuation).  Returns
    ``(x_profile, y_profile, s_profile)``.
    """
    del start   # the first leg starts there
    s_profile = plan_path(legs, start_speed, origin_ns)
    x_profile, y_profile = follow_path(legs, s_profile)
    return x_profile, y_profile, s_profile
