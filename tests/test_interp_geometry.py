"""Interpolation geometry and timing (cml-users-guide.txt 4.4.1–4.4.3).

Endpoints are exact, sampled points lie on the documented arc or line within 1 pulse,
the direction and the major/minor choice match 4.4, and the path speed never exceeds S.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from coolmuscle.motor.motion.interp import (
    _CHECK_SPEED_ERROR,
    MAX_ERROR,
    MIN_PIECE,
    Arc,
    Leg,
    Line,
    PathError,
    SpiralArc,
    SubPath,
    _knots,
    _pieces,
    arc_from_center,
    arc_from_radius,
    follow_path,
    plan_interpolation,
    plan_path,
)
from coolmuscle.motor.motion.planner import limits_from_data, plan_stop

S100_A100 = limits_from_data(100, 100, k37=3, k44=100, k51=0, k69=0)   # 10000 pps path speed


def samples(x_profile, y_profile, n=400):
    end = x_profile.end_ns
    for i in range(n + 1):
        t = x_profile.origin_ns + (end - x_profile.origin_ns) * i // n
        yield t, x_profile.position_at(t), y_profile.position_at(t)


def check_on_ellipse(xp, yp, center, rx, ry):
    for _, x, y in samples(xp, yp):
        # distance to the ellipse, approximated by the radial error on the unit circle
        ux, uy = (x - center[0]) / rx, (y - center[1]) / ry
        radial = math.hypot(ux, uy)
        assert abs(radial - 1) * min(rx, ry) <= 1.0, (x, y)


def orientation(xp, yp, center):
    """Sum of the z cross product (p - c) x dp: negative = clockwise."""
    total = 0.0
    pts = list(samples(xp, yp, 50))
    for (_, x0, y0), (_, x1, y1) in zip(pts, pts[1:]):
        total += (x0 - center[0]) * (y1 - y0) - (y0 - center[1]) * (x1 - x0)
    return total


@pytest.mark.parametrize("minor, cw", [(False, True), (True, False), (True, True),
                                        (False, False)])
def test_4_4_1_radius_arc_major_minor_and_direction(minor: bool, cw: bool) -> None:
    """4.4.1: from (0,0) to (1000,1000), R=2000: four trajectories, + CW / - CCW."""
    path = arc_from_radius((0, 0), (1000, 1000), 2000, 2000, minor=minor, cw=cw)
    assert isinstance(path, Arc)
    assert (abs(path.sweep) <= math.pi) == minor
    assert (path.sweep < 0) == cw
    xp, yp, sp = plan_interpolation((0, 0), 0.0, [Leg(path, S100_A100)], 0)
    assert xp.final_position == 1000 and yp.final_position == 1000
    assert xp.position_at(xp.end_ns) == pytest.approx(1000, abs=1e-6)
    assert yp.position_at(yp.end_ns) == pytest.approx(1000, abs=1e-6)
    check_on_ellipse(xp, yp, path.center, path.rx, path.ry)
    assert (orientation(xp, yp, path.center) < 0) == cw
    chord_angle = 2 * math.asin(math.dist((0, 0), (1000, 1000)) / 2 / 2000)
    expected = chord_angle if minor else 2 * math.pi - chord_angle
    assert path.length == pytest.approx(2000 * expected, rel=1e-9)


def test_4_4_2_center_arc_cw_and_ccw() -> None:
    """4.4.2: centre N=(-823, 1823), from (0,0) to (1000,1000)."""
    for cw in (True, False):
        path = arc_from_center((0, 0), (1000, 1000), (-823, 1823), cw=cw)
        xp, yp, _ = plan_interpolation((0, 0), 0.0, [Leg(path, S100_A100)], 0)
        r = math.dist((0, 0), (-823, 1823))
        check_on_ellipse(xp, yp, (-823, 1823), r, r)
        assert (orientation(xp, yp, (-823, 1823)) < 0) == cw
        assert xp.position_at(xp.end_ns) == pytest.approx(1000, abs=1e-6)


def test_4_4_3_radius_zero_is_a_straight_line() -> None:
    path = arc_from_radius((0, 0), (1000, 1000), 0, 0, minor=False, cw=True)
    assert isinstance(path, Line)
    xp, yp, sp = plan_interpolation((0, 0), 0.0, [Leg(path, S100_A100)], 0)
    for _, x, y in samples(xp, yp):
        assert abs(x - y) <= 1e-6
    assert sp.end_ns == xp.end_ns


def test_oval_with_different_radii_per_axis() -> None:
    path = arc_from_radius((0, 0), (3000, 1000), 3000, 1000, minor=True, cw=False)
    xp, yp, _ = plan_interpolation((0, 0), 0.0, [Leg(path, S100_A100)], 0)
    check_on_ellipse(xp, yp, path.center, 3000, 1000)


def test_full_circle_by_centre() -> None:
    path = arc_from_center((0, 0), (0, 0), (500, 0), cw=True)
    assert path.sweep == pytest.approx(-2 * math.pi)
    xp, yp, _ = plan_interpolation((0, 0), 0.0, [Leg(path, S100_A100)], 0)
    check_on_ellipse(xp, yp, (500, 0), 500, 500)


def test_arc_by_radius_needs_two_points() -> None:
    with pytest.raises(PathError):
        arc_from_radius((5, 5), (5, 5), 100, 100, minor=True, cw=True)


def test_merge_through_two_legs_does_not_stop_at_the_junction() -> None:
    line = Line((0, 0), (2000, 0))
    arc = arc_from_radius((2000, 0), (3000, 1000), 1000, 1000, minor=True, cw=False)
    xp, yp, sp = plan_interpolation((0, 0), 0.0, [Leg(line, S100_A100), Leg(arc, S100_A100)], 0)
    t_junction = sp.first_crossing(2000.0, 0)
    assert t_junction is not None and sp.velocity_at(t_junction) > 1000
    assert xp.position_at(xp.end_ns) == pytest.approx(3000, abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(x1=st.integers(-20000, 20000), y1=st.integers(-20000, 20000),
       r=st.integers(1, 50000), minor=st.booleans(), cw=st.booleans(),
       s=st.integers(1, 300), a=st.integers(1, 500))
def test_path_speed_never_exceeds_s_and_points_stay_on_the_arc(x1, y1, r, minor, cw, s, a):
    if (x1, y1) == (0, 0):
        return
    path = arc_from_radius((0, 0), (x1, y1), r, r, minor=minor, cw=cw)
    lim = limits_from_data(s, a, k37=3, k44=100, k51=0, k69=0)
    xp, yp, sp = plan_interpolation((0, 0), 0.0, [Leg(path, lim)], 0)
    assert xp.position_at(xp.end_ns) == pytest.approx(x1, abs=1e-6)
    assert yp.position_at(yp.end_ns) == pytest.approx(y1, abs=1e-6)
    if isinstance(path, Arc):
        check_on_ellipse(xp, yp, path.center, path.rx, path.ry)
    for t, _, _ in samples(xp, yp, 200):
        speed = math.hypot(xp.velocity_at(t), yp.velocity_at(t))
        assert speed <= lim.speed * (1 + 1e-3) + 1e-6


@settings(max_examples=40, deadline=None)
@given(x1=st.integers(-20000, 20000), y1=st.integers(-20000, 20000),
       rx=st.integers(50, 50000), ratio=st.floats(0.05, 20), minor=st.booleans(),
       cw=st.booleans(), s=st.integers(1, 300), a=st.integers(1, 500),
       k51=st.sampled_from([0, 5]), k69=st.sampled_from([0, 512, 1024]))
# a half oval of axis ratio 25 (ry = round(2.5) = 2) at S=1: 10-15 s of CPU each before the
# arc-length table was refined at the oval's tips (FLAT_OVALS below)
@example(x1=20000, y1=0, rx=50, ratio=0.05, minor=False, cw=False, s=1, a=1, k51=0, k69=0)
@example(x1=20000, y1=0, rx=50, ratio=0.05, minor=True, cw=True, s=1, a=1, k51=0, k69=0)
def test_ovals_stay_on_the_ellipse_at_the_path_speed(x1, y1, rx, ratio, minor, cw, s, a,
                                                     k51, k69):
    """Different radii per axis (2.2.2 "R": an oval): on the ellipse, speed at most S
    (within MAX_SPEED_ERROR), also with creep speed K51 and S-curves K69."""
    if (x1, y1) == (0, 0):
        return
    ry = max(1, round(rx * ratio))
    path = arc_from_radius((0, 0), (x1, y1), rx, ry, minor=minor, cw=cw)
    lim = limits_from_data(s, a, k37=3, k44=100, k51=k51, k69=k69)
    xp, yp, _ = plan_interpolation((0, 0), 0.0, [Leg(path, lim)], 0)
    assert (xp.final_position, yp.final_position) == (x1, y1)
    for t, x, y in samples(xp, yp, 300):
        ux, uy = (x - path.center[0]) / path.rx, (y - path.center[1]) / path.ry
        f = ux * ux + uy * uy - 1
        grad = math.hypot(2 * ux / path.rx, 2 * uy / path.ry) or 1.0
        assert abs(f) / grad <= 0.1
        assert math.hypot(xp.velocity_at(t), yp.velocity_at(t)) <= lim.speed * (1 + 1e-4)


# flat ovals (2.2.2 "R": different radii) that cost 10 s to a minute of CPU each before
# the arc-length table was refined at their tips and Newton's method kept in its step:
# the axis ratios are 25, 1000, 30000 and 1e9 (the largest R, 1e9, against 1)
FLAT_OVALS = [(20000, 0, 50, 2, False), (3, 0, 1000, 1, True), (-20000, 13, 30000, 1, True),
              (3, 0, 10**9, 1, True)]


@pytest.mark.parametrize("x1, y1, rx, ry, cw", FLAT_OVALS)
def test_flat_oval_work_is_bounded_by_its_turn(x1: int, y1: int, rx: int, ry: int,
                                               cw: bool) -> None:
    """At S=1 the work to follow a flat oval grows with the angle it turns, not with how
    flat it is.

    A cubic piece turning by φ on a circle misses the path speed by φ³/128 of it at its
    check points, so a piece that just meets the check turns φ0 = (128 x the check's
    error)^(1/3) ≈ 0.19 rad, and halving leaves pieces of at least φ0/2: a circle needs
    at most 2|sweep|/φ0 pieces between the knots of the path profile.  The tips of an
    oval (curvature changing fast) may need a few times more; the bound allows six.  The
    pieces are the leaves of the halving, so they bound the work (2 x pieces calls).
    Before the fix these ovals took 45873, 36638, 26879 and 40464 pieces (bounds 206,
    409, 206, 409): near a tip the table's speed was off by up to 5e-5, or Newton's
    method flew off the oval, and no piece, however short, could meet the check.
    """
    path = arc_from_radius((0, 0), (x1, y1), rx, ry, minor=False, cw=cw)
    assert isinstance(path, Arc)
    lim = limits_from_data(1, 1, k37=3, k44=100, k51=0, k69=0)
    xp, yp, sp = plan_interpolation((0, 0), 0.0, [Leg(path, lim)], 0)
    phi0 = (128 * _CHECK_SPEED_ERROR) ** (1 / 3)
    knot_intervals = len(_knots(sp, [0.0])) - 1
    assert len(xp.segments) <= knot_intervals + 6 * 2 * abs(path.sweep) / phi0
    assert (xp.final_position, yp.final_position) == (x1, y1)


def oval_tips(path: Arc) -> list[float]:
    """Arc lengths near the ends of the oval's long axis (and the path's own ends)."""
    axis = 1 if path.rx > path.ry else 0          # the tips lie on the long axis
    grid = [path.length * i / 4000 for i in range(4001)]
    side = [path.point(s)[axis] - path.center[axis] for s in grid]
    return [0.0, path.length] + [a for a, u, v in zip(grid, side, side[1:]) if u * v <= 0]


@pytest.mark.parametrize("x1, y1, rx, ry, cw", FLAT_OVALS[:2])
def test_flat_oval_points_move_at_the_arc_length(x1: int, y1: int, rx: int, ry: int,
                                                 cw: bool) -> None:
    """4.4 "synthetic speed by 2 axes": the point at arc length s moves by ds along the
    oval within 1e-6, also through its tips (before the fix: 5.4e-5 at the last tip of
    the half oval of ratio 25, up to 1.2e-3 at the tips of the full oval of ratio 1000).
    Chords of 1/2000 of the tip's radius of curvature (ry²/rx) are shorter than their
    arcs by 4e-8; the allowance adds the floats' resolution over such a chord."""
    path = arc_from_radius((0, 0), (x1, y1), rx, ry, minor=False, cw=cw)
    assert isinstance(path, Arc)
    d = path.ry ** 2 / path.rx / 2000
    floats = math.ulp(max(path.rx, abs(path.center[0]))) + math.ulp(path.length)
    resolution = 4 * floats / (2 * d)
    assert resolution < 1e-5
    around = [tip + 2 * path.ry ** 2 / path.rx * j / 100 for tip in oval_tips(path)
              for j in range(-100, 101)]
    for s in around + [path.length * i / 500 for i in range(501)]:
        s = min(max(s, d), path.length - d)
        step = math.dist(path.point(s - d), path.point(s + d)) / (2 * d)
        assert abs(step - 1) <= 1e-6 + resolution, s


@pytest.mark.parametrize("x1, y1, rx, ry, cw", FLAT_OVALS)
def test_flat_oval_points_stay_on_the_oval_at_their_arc_length(x1: int, y1: int, rx: int,
                                                               ry: int, cw: bool) -> None:
    """Points at arc lengths s and s + ds lie on the oval no farther apart than ds, near
    the tips too (before the fix, Newton's method from the tip of the 1e9 oval put the
    point 3e4 pulses past the tip at 5e8 pulses from its neighbours, on the oval but at
    the wrong arc length)."""
    path = arc_from_radius((0, 0), (x1, y1), rx, ry, minor=False, cw=cw)
    assert isinstance(path, Arc)
    floats = 4 * math.ulp(max(path.rx, path.ry, math.hypot(*path.center)))
    near = [tip + path.length * 0.5 ** k * sign for tip in oval_tips(path)
            for k in range(8, 50) for sign in (-1, 1)]
    for s in near + [path.length * i / 1000 for i in range(1001)]:
        s = min(max(s, 0.0), path.length - 1.0)
        a, b = path.point(s), path.point(s + 1.0)
        assert math.dist(a, b) <= 1.0 + 1e-6 + floats, s
        for x, y in (a, b):
            ux, uy = (x - path.center[0]) / path.rx, (y - path.center[1]) / path.ry
            assert abs(math.hypot(ux, uy) - 1) * min(path.rx, path.ry) <= MAX_ERROR, s


def test_pieces_stop_where_the_clock_cannot_halve_them() -> None:
    """A path lasting years (R 1e9 against 1 with a far end) puts its pieces at times
    whose float step exceeds MIN_PIECE; a piece two float steps long is not halved into
    an empty one (which raised ZeroDivisionError through the chain before)."""
    class Restless:
        """A sampler whose speed never matches a cubic piece: every check fails."""

        def state(self, t: float) -> tuple[float, float, float, float]:
            return 0.0, 0.0, 1e3 * math.sin(1e7 * t), 0.0

    t0 = 2e11
    t1 = math.nextafter(math.nextafter(t0, math.inf), math.inf)
    assert t1 - t0 > MIN_PIECE
    pieces = _pieces(Restless(), t0, t1)     # type: ignore[arg-type]
    assert all(p0 < p1 for p0, p1 in pieces) and pieces[0][0] == t0 and pieces[-1][1] == t1


def test_centre_farther_from_the_end_draws_a_spiral_to_the_exact_end() -> None:
    path = arc_from_center((0, 0), (1200, 0), (500, 0), cw=False)
    assert isinstance(path, SpiralArc)
    xp, yp, _ = plan_interpolation((0, 0), 0.0, [Leg(path, S100_A100)], 0)
    radii = [math.dist((x, y), (500, 0)) for _, x, y in samples(xp, yp)]
    assert radii[0] == pytest.approx(500) and radii[-1] == pytest.approx(700)
    assert all(r0 <= r1 + 0.1 for r0, r1 in zip(radii, radii[1:]))
    assert (xp.final_position, yp.final_position) == (1200, 0)


def test_stop_part_way_follows_the_path_and_the_rest_resumes_there() -> None:
    """A stop re-plans only the path length; the axes stay on the arc (2.1.2 "]")."""
    path = arc_from_center((0, 0), (0, 0), (1000, 0), cw=True)
    legs = [Leg(path, S100_A100)]
    s_profile = plan_path(legs, 0.0, 0)
    t = s_profile.origin_ns + 300_000_000
    stop = plan_stop(s_profile.state_at(t), S100_A100.decel, t)
    xp, yp = follow_path(legs, stop)
    for i in range(101):
        tt = t + (stop.end_ns - t) * i // 100
        assert abs(math.dist((xp.position_at(tt), yp.position_at(tt)), (1000, 0)) - 1000) < 0.1
    rest = SubPath(path, stop.final_position)
    assert rest.length == pytest.approx(path.length - stop.final_position)
    assert math.dist(rest.point(0), (xp.final_position, yp.final_position)) < 1e-6
    xr, yr, _ = plan_interpolation(rest.point(0), 0.0, [Leg(rest, S100_A100)], stop.end_ns)
    assert (xr.final_position, yr.final_position) == (0, 0)
