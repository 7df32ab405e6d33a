"""Property tests of the planner and profiles (hypothesis): limits, exactness,
continuity, merge passing speeds, numerical integration, first crossings.

Random S, A, K37, K44, K51, K69, distances and (for re-planning) start states taken
from a running profile.  The checks are analytic per segment (extrema of the
velocity quadratic, ends of the linear acceleration) plus a dense grid through the
public evaluation methods.
"""

from __future__ import annotations

import math
import os
from bisect import bisect_left, bisect_right

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coolmuscle.motor.motion.planner import (
    Limits,
    Waypoint,
    limits_from_data,
    minimum_time,
    plan_moves,
    plan_stop,
    plan_velocity,
)
from coolmuscle.motor.motion.profile import Profile, Segment
from coolmuscle.motor.state import units

NS = 1_000_000_000
#: Multiply the example counts for a long local run: COOLMUSCLE_STRESS=50 pytest ...
STRESS = int(os.environ.get("COOLMUSCLE_STRESS", "1"))


def examples(count: int) -> settings:
    return settings(max_examples=count * STRESS, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


SETTINGS = examples(100)
REL = 1e-9


# -- strategies ----------------------------------------------------------------------
@st.composite
def params(draw: st.DrawFn) -> dict[str, int]:
    """Global K parameters: K37, K44, K51, K69."""
    return {
        "k37": draw(st.sampled_from(sorted(units.RESOLUTIONS))),
        "k44": draw(st.one_of(st.just(100), st.integers(1, 500))),
        "k51": draw(st.one_of(st.just(0), st.integers(0, 1000))),
        "k69": draw(st.one_of(st.just(0), st.just(1024), st.integers(0, 1024))),
    }


@st.composite
def limits(draw: st.DrawFn, k: dict[str, int]) -> Limits:
    """Limits from random S and A data (negative values allowed) and ``k``."""
    s = draw(st.integers(1, 32767)) * draw(st.sampled_from([1, -1]))
    a = draw(st.one_of(st.integers(1, 32767), st.integers(1, 300)))
    decel = draw(st.one_of(st.none(), st.integers(1, 32767)))
    return limits_from_data(s, a, decel_a_value=decel, **k)


def distances(speed: float) -> st.SearchStrategy[float]:
    """Move lengths from a fraction of a pulse to about 20 s of travel."""
    top = max(1.0, min(1e9, speed * 20.0))
    return st.one_of(st.floats(0.001, top), st.integers(1, int(top)).map(float))


@st.composite
def merge_case(draw: st.DrawFn, count: int = 5) -> tuple[float, list[Waypoint]]:
    """A start position and 1..count waypoints (reversals and repeats allowed)."""
    k = draw(params())
    start = float(draw(st.integers(-10**6, 10**6)))
    here, points = start, []
    for _ in range(draw(st.integers(1, count))):
        lim = draw(limits(k))
        step = draw(st.one_of(distances(lim.speed), st.just(0.0)))
        here += step * draw(st.sampled_from([1, 1, -1]))
        points.append(Waypoint(here, lim))
    return start, points


# -- analytic helpers ----------------------------------------------------------------
def v_extremes(seg: Segment, lo: float = 0.0, hi: float | None = None) -> list[float]:
    """Velocities at the ends of [lo, hi] and at the acceleration root inside."""
    hi = seg.duration if hi is None else hi
    taus = [lo, hi]
    if seg.j != 0.0 and lo < -seg.a / seg.j < hi:
        taus.append(-seg.a / seg.j)
    return [seg.velocity(t) for t in taus]


def p_candidates(seg: Segment, lo: float, hi: float) -> list[float]:
    """Positions at the ends of [lo, hi] and at velocity roots inside."""
    taus = [lo, hi]
    if seg.j != 0.0:
        disc = seg.a * seg.a - 2.0 * seg.j * seg.v
        if disc >= 0.0:
            taus += [(-seg.a + s * math.sqrt(disc)) / seg.j for s in (1.0, -1.0)]
    elif seg.a != 0.0:
        taus.append(-seg.v / seg.a)
    return [seg.position(t) for t in taus if lo <= t <= hi]


def span_limits(profile: Profile, seg: Segment, bounds: list[Limits]) -> list[Limits]:
    """Limits of the waypoint a segment moves toward (passing points fall on segment
    boundaries).  A segment shorter than the clock's resolution at its instant sits
    on a boundary: either side's limits may apply."""
    times = [t for t, _ in profile.passing_times]
    sides = {bisect_left(times, seg.end)}
    if seg.end == seg.start:
        sides.add(bisect_right(times, seg.end))
    return [bounds[profile.passing_times[k][1] if k < len(times) else -1] for k in sides]


def limits_of(profile: Profile, seg: Segment, bounds: list[Limits]) -> Limits:
    return span_limits(profile, seg, bounds)[0]


def active_limits(profile: Profile, t_ns: int, bounds: list[Limits]) -> Limits:
    """Limits of the span running at ``t_ns`` (the state there respects them)."""
    rel = (t_ns - profile.origin_ns) / NS
    for seg in profile.segments:
        if seg.start <= rel < seg.end:
            return limits_of(profile, seg, bounds)
    return bounds[-1]


def direction(seg: Segment) -> float:
    """Direction of motion in a segment (ramps never reverse; speed may touch 0)."""
    length = min(seg.duration, 1e9)
    v = max((seg.velocity(length * f) for f in (0.0, 0.25, 0.5, 0.75, 1.0)), key=abs)
    return math.copysign(1.0, v) if v != 0.0 else 0.0


def check_limits(profile: Profile, bounds: list[Limits], speed_over: float = 0.0,
                 jerk_over: float = 0.0) -> None:
    """|v| <= S, accel <= A, decel <= D and |j| <= K69 jerk, per span (analytic).

    ``speed_over``/``jerk_over``: what a re-planned motion may inherit from the
    running one (its speed plus the drift of its acceleration; its jerk)."""
    for seg in profile.segments:
        problems = [segment_problem(seg, lim, speed_over, jerk_over)
                    for lim in span_limits(profile, seg, bounds)]
        assert None in problems, (seg, problems)


def segment_problem(seg: Segment, lim: Limits, speed_over: float,
                    jerk_over: float) -> str | None:
    """What of S, A, D, jerk one segment exceeds under ``lim`` (None: nothing)."""
    top = max(lim.speed, speed_over)
    finite = seg.duration if not math.isinf(seg.duration) else 1.0
    if max(abs(v) for v in v_extremes(seg, 0.0, finite)) > top * (1 + REL) + 1e-9:
        return "speed"
    d = direction(seg)
    for a in (seg.a, seg.acceleration(finite)):
        cap = lim.accel if a * d > 0.0 else lim.decel if a * d < 0.0 else 0.0
        if abs(a) > max(cap, 0.0) * (1 + REL) + 1e-9:
            return "acceleration"
    if abs(seg.j) > max(lim.max_jerk, jerk_over) * (1 + REL):
        return "jerk"
    return None


def top_creep(bounds: list[Limits]) -> float:
    return max(lim.creep for lim in bounds)


def is_creep_jump(v_from: float, v_to: float, creep: float, scale: float) -> bool:
    """A documented velocity jump (K51): a stop from at most the creep speed to 0,
    a start from 0 to at most the creep speed, or both at the same instant."""
    tol = REL * scale + 1e-9
    return abs(v_from) <= creep + tol and abs(v_to) <= creep + tol


def check_continuity(profile: Profile, bounds: list[Limits]) -> None:
    """p, v continuous (except creep jumps), a continuous under S-curve."""
    segs = profile.segments
    if not segs:
        return
    pscale = max(1.0, abs(profile.start_state[0]), abs(profile.final_position)
                 if math.isfinite(profile.final_position) else 1.0)
    vscale = max([lim.speed for lim in bounds] + [abs(profile.start_state[1])])
    ascale = max(max(lim.accel, lim.decel) for lim in bounds)
    scurve = all(lim.scurve > 0 for lim in bounds)
    creeps = top_creep(bounds)
    prev = profile.start_state
    for seg in segs:
        assert abs(seg.p - prev[0]) <= 1e-12 * pscale * 10 + 1e-9
        if abs(seg.v - prev[1]) > REL * vscale + 1e-9:
            assert is_creep_jump(prev[1], seg.v, creeps, vscale), (prev, seg)
        elif scurve:
            assert abs(seg.a - prev[2]) <= 1e-6 * ascale, (prev, seg)
        if math.isinf(seg.duration):
            return
        prev = seg.end_state()
    assert abs(prev[0] - profile.final_position) <= 1e-6 + 1e-15 * pscale
    if abs(prev[1]) > REL * vscale + 1e-9:
        assert is_creep_jump(prev[1], 0.0, creeps, vscale)
    if scurve:
        assert abs(prev[2]) <= 1e-6 * ascale


def grid(profile: Profile, n: int = 600) -> list[int]:
    """Dense grid plus every segment boundary (and 1 ns either side)."""
    end = profile.end_ns if profile.end_ns is not None else profile.origin_ns + 5 * NS
    span = max(1, end - profile.origin_ns)
    times = {profile.origin_ns + span * i // n for i in range(n + 1)}
    for seg in profile.segments:
        if math.isfinite(seg.start):
            b = profile.origin_ns + round(seg.start * NS)
            times.update((b - 1, b, b + 1))
    return sorted(times)


def check_grid(profile: Profile, top: float, bounds: list[Limits]) -> None:
    """Public evaluation on a grid: |v| <= top and |a| <= max(A, D)."""
    amax = max(max(lim.accel, lim.decel) for lim in bounds)
    for t in grid(profile):
        p, v, a = profile.state_at(t)
        assert (p, v, a) == (profile.position_at(t), profile.velocity_at(t),
                             profile.acceleration_at(t))
        assert abs(v) <= top * (1 + REL) + 1e-9
        assert abs(a) <= amax * (1 + REL)


def check_final(profile: Profile, target: float) -> None:
    assert profile.final_position == target
    assert profile.end_ns is not None
    assert profile.position_at(profile.end_ns) == target
    assert profile.velocity_at(profile.end_ns) == 0.0
    if profile.segments:
        last = profile.segments[-1]
        assert abs(last.end_state()[0] - target) <= 1e-6 + 1e-15 * abs(target)


def integrate(profile: Profile, bounds: list[Limits], h: float = 1e-6,
              cap: int = 100_000) -> None:
    """Trapezoid-integrate the acceleration (documented creep jumps added) and
    compare with the closed-form position within 1 pulse.  Steps of 1 µs, at most
    ``cap`` per segment (longer segments use coarser steps; the rule is exact for
    the linear acceleration of a segment, its error on position is O(h²·Δa))."""
    p, v, _ = profile.start_state
    vscale = max([lim.speed for lim in bounds] + [abs(v)])
    creeps = top_creep(bounds)
    for seg in profile.segments:
        if abs(seg.v - float(v)) > REL * vscale + 1e-6:
            assert is_creep_jump(float(v), seg.v, creeps, vscale)
            v = np.longdouble(seg.v)
        length = seg.duration if math.isfinite(seg.duration) else 2.0
        n = int(min(cap, max(2, math.ceil(length / h))))
        tau = np.linspace(0.0, length, n + 1, dtype=np.longdouble)
        dt = tau[1] - tau[0]
        acc = seg.a + seg.j * tau
        zero = np.zeros(1, dtype=np.longdouble)  # long double: the reference must not
        vel = v + np.concatenate((zero, np.cumsum((acc[1:] + acc[:-1]) * dt / 2)))  # drift
        pos = p + np.concatenate((zero, np.cumsum((vel[1:] + vel[:-1]) * dt / 2)))
        for i in (n // 3, 2 * n // 3, n):
            t_ns = profile.origin_ns + round((seg.start + tau[i]) * NS)
            if profile.end_ns is not None and t_ns >= profile.end_ns:
                t_ns = profile.end_ns - 1
            assert abs(profile.position_at(t_ns) - float(pos[i])) <= 1.0, (seg, pos[i])
        p, v = pos[-1], vel[-1]
        if math.isinf(seg.duration):
            return
    assert abs(float(p) - profile.final_position) <= 1.0


def check_all(profile: Profile, bounds: list[Limits], speed_over: float = 0.0) -> None:
    check_limits(profile, bounds, speed_over)
    check_continuity(profile, bounds)
    check_grid(profile, max([lim.speed for lim in bounds] + [speed_over]), bounds)


# -- point to point --------------------------------------------------------------------
@SETTINGS
@given(k=params(), data=st.data())
def test_ptp_limits_exact_and_minimum_time(k: dict[str, int], data: st.DataObject) -> None:
    lim = data.draw(limits(k))
    far = st.floats(1e6, 2e9)  # up to the K37 position range, long cruises
    dist = data.draw(st.one_of(distances(lim.speed), far)) * data.draw(st.sampled_from([1, -1]))
    start = float(data.draw(st.integers(-10**6, 10**6)))
    prof = plan_moves((start, 0.0, 0.0), [Waypoint(start + dist, lim)], 7 * NS)
    check_final(prof, start + dist)
    check_all(prof, [lim])
    if lim.scurve == 0:
        expected = minimum_time((start + dist) - start, lim)
        assert math.isclose(prof.duration, expected, rel_tol=1e-9, abs_tol=1e-12)
        assert abs(prof.end_ns - 7 * NS - expected * NS) <= max(1.0, expected * NS * 1e-15)
    else:
        assert prof.duration >= minimum_time((start + dist) - start, lim) * (1 - 1e-9)


# -- merge motion ------------------------------------------------------------------------
def reverses_at(points: list[float], start: float, index: int) -> bool:
    """Whether the path turns round at waypoint ``index`` (ignoring repeats)."""
    here = points[index]
    before = [p for p in [start, *points[:index]] if p != here]
    after = [p for p in points[index + 1:] if p != here]
    if not before or not after:
        return True
    return (here - before[-1]) * (after[0] - here) < 0.0


@SETTINGS
@given(case=merge_case())
def test_merge_limits_and_passing_speed(case: tuple[float, list[Waypoint]]) -> None:
    start, points = case
    prof = plan_moves((start, 0.0, 0.0), points, 0)
    check_final(prof, points[-1].target)
    bounds = [w.limits for w in points]
    check_all(prof, bounds)
    targets = [w.target for w in points]
    passing = prof.passing_times_ns()
    for t_ns, index in passing:
        assert abs(prof.position_at(t_ns) - targets[index]) <= (
            1e-6 * max(1.0, abs(targets[index])) + abs(prof.velocity_at(t_ns)) * 1e-9)
        if not reverses_at(targets, start, index):
            assert prof.velocity_at(t_ns) != 0.0
            assert abs(prof.velocity_at(t_ns - 1)) > 0.0
    for seg in prof.segments:  # no stop inside a run: zero speed only at run ends
        if seg.v == 0.0 and seg.start > 0.0:
            t_ns = round(seg.start * NS)
            near = [abs(prof.position_at(t_ns) - x) for x in targets]
            assert min(near) <= 1e-6 * max(1.0, max(map(abs, targets))) + 1e-6


# -- re-planning on the fly ---------------------------------------------------------------
@SETTINGS
@given(case=merge_case(count=3), frac=st.floats(0.0, 1.0), data=st.data())
def test_replan_from_moving_state(case: tuple[float, list[Waypoint]], frac: float,
                                  data: st.DataObject) -> None:
    start, points = case
    first = plan_moves((start, 0.0, 0.0), points, 0)
    cut = round(first.end_ns * frac)
    state = first.state_at(cut)
    bounds = [w.limits for w in points]
    old = active_limits(first, cut, bounds)
    if old.scurve:  # same A, D, K69 (a consistent acceleration), maybe a new S
        speed = data.draw(st.sampled_from([old.speed, old.speed / 2, old.speed * 2]))
        new = Limits(speed, old.accel, old.decel, min(old.creep, speed), old.scurve)
    else:
        new = data.draw(limits({"k37": 3, "k44": 100, "k51": 0, "k69": 0}))
    target = state[0] + data.draw(distances(new.speed)) * data.draw(st.sampled_from([1, -1]))
    prof = plan_moves(state, [Waypoint(target, new)], cut)
    assert prof.state_at(cut - 1) == state
    assert abs(prof.position_at(cut) - state[0]) <= 1e-9 * max(1.0, abs(state[0]))
    check_final(prof, target)
    drift = state[2] ** 2 / (2.0 * min(new.jerk_accel, new.jerk_decel))
    bounds = [new, *bounds]
    check_continuity(prof, bounds)
    over = abs(state[1]) + drift
    check_limits(prof, [new], speed_over=over, jerk_over=old.max_jerk)
    check_grid(prof, max(new.speed, over), bounds)
    integrate(prof, bounds)


@SETTINGS
@given(case=merge_case(count=2), frac=st.floats(0.0, 1.0), data=st.data())
def test_continuous_rotation_and_stops(case: tuple[float, list[Waypoint]], frac: float,
                                       data: st.DataObject) -> None:
    start, points = case
    first = plan_moves((start, 0.0, 0.0), points, 0)
    cut = round(first.end_ns * frac)
    state = first.state_at(cut)
    lim = active_limits(first, cut, [w.limits for w in points])
    over = abs(state[1]) + state[2] ** 2 / (2.0 * min(lim.jerk_accel, lim.jerk_decel))
    velocity = data.draw(st.sampled_from([lim.speed, -lim.speed, 0.0, lim.speed / 3]))
    run = plan_velocity(state, velocity, lim, cut)
    check_continuity(run, [lim])
    check_limits(run, [lim], speed_over=over)
    if velocity:
        assert run.end_ns is None and run.final_position == math.copysign(math.inf, velocity)
        assert run.velocity_at(cut + 10**6 * NS) == velocity
        assert run.segments[-1].duration == math.inf
    else:
        assert run.end_ns is not None and run.velocity_at(run.end_ns) == 0.0
    stop = plan_stop(state, lim.decel, cut, lim.scurve, creep=lim.creep, speed=lim.speed)
    check_continuity(stop, [lim])
    # decelerating, the first ramp may steepen to a²/2|v| so the speed does not cross
    # zero (docs/fidelity.md "S-curve re-plan"): a state with a tiny speed inherits it
    unwind = (state[2] ** 2 / (2.0 * abs(state[1]))
              if state[1] and state[1] * state[2] < 0.0 else 0.0)
    check_limits(stop, [lim], speed_over=over, jerk_over=unwind)
    integrate(stop, [lim])
    if state[1] != 0.0 and state[2] * state[1] <= 0.0:  # no overshoot: not past the stop
        assert (stop.final_position - state[0]) * state[1] >= 0.0


# -- numerical integration -----------------------------------------------------------------
@examples(40)
@given(case=merge_case(count=3))
def test_closed_form_matches_numerical_integration(case: tuple[float, list[Waypoint]]) -> None:
    start, points = case
    prof = plan_moves((start, 0.0, 0.0), points, 3 * NS)
    integrate(prof, [w.limits for w in points])


# -- first crossing ------------------------------------------------------------------------
def signed_range(profile: Profile, x: float, a_ns: int, b_ns: int) -> tuple[float, float]:
    """min and max of (position - x) over [a_ns, b_ns] (analytic per segment)."""
    vals = [profile.position_at(a_ns) - x, profile.position_at(b_ns) - x]
    lo_rel = (a_ns - profile.origin_ns) / NS
    hi_rel = (b_ns - profile.origin_ns) / NS
    for seg in profile.segments:
        lo, hi = max(lo_rel, seg.start), min(hi_rel, seg.end)
        if lo < hi:
            vals += [p - x for p in p_candidates(seg, lo - seg.start, hi - seg.start)]
    return min(vals), max(vals)


@examples(150)
@given(case=merge_case(count=4), data=st.data())
def test_first_crossing_is_exact_and_first(case: tuple[float, list[Waypoint]],
                                           data: st.DataObject) -> None:
    start, points = case
    prof = plan_moves((start, 0.0, 0.0), points, 5 * NS)
    if data.draw(st.booleans()):
        at = 5 * NS + data.draw(st.integers(0, prof.end_ns - 5 * NS))
        prof = plan_velocity(prof.state_at(at),
                             -points[0].limits.speed, points[0].limits, 5 * NS)
    end = prof.end_ns if prof.end_ns is not None else 5 * NS + 20 * NS
    lo, hi = min(start, *(w.target for w in points)), max(start, *(w.target for w in points))
    x = data.draw(st.one_of(st.floats(lo - 10, hi + 10),
                            st.sampled_from([start] + [w.target for w in points])))
    after = data.draw(st.integers(5 * NS - NS, end + NS))
    t = prof.first_crossing(x, after)
    tol = 1e-9 * max(1.0, abs(x))
    before = prof.position_at(after) - x
    if t is None:
        low, high = signed_range(prof, x, after, end + NS)
        assert low > tol or high < -tol
        return
    assert t >= after
    vnear = max(abs(prof.velocity_at(t + d)) for d in (-1, 0, 1))
    assert abs(prof.position_at(t) - x) <= vnear * 1e-9 + 10 * tol
    if t - 1 >= after and abs(before) > tol:  # never at or past x before t
        low, high = signed_range(prof, x, after, t - 1)
        if before > 0:
            assert low >= -vnear * 2e-9 - tol
        else:
            assert high <= vnear * 2e-9 + tol
        margin = vnear * 2e-9 + tol
        if t - 2 >= after:
            low, high = signed_range(prof, x, after, t - 2)
            assert (low > -margin) if before > 0 else (high < margin)


def test_time_speed_below_hits_the_speed() -> None:
    lim = limits_from_data(100, 100, k37=3, k44=50, k51=0, k69=512)
    prof = plan_moves((0.0, 0.0, 0.0), [Waypoint(30000.0, lim)], 0)
    starts = [round(s.start * NS) for s in prof.segments]
    t = prof.time_speed_below(2500.0, starts[2])
    assert t is not None and abs(abs(prof.velocity_at(t)) - 2500.0) < 1e-3
    assert bisect_right(starts, t) >= 3
    for probe in range(starts[2], t, max(1, (t - starts[2]) // 500)):
        assert abs(prof.velocity_at(probe)) > 2500.0 - 1e-6


def test_stop_from_a_nearly_still_decelerating_state() -> None:
    """Regression (hypothesis found it): v = 2e-13 pps, a = -0.005 pulses/s², K69 = 64.
    The stop steepens its ramp to a²/2|v| rather than let the speed cross zero."""
    lim = Limits(190.0, 19000.0, 19000.0, 0.0, 64)
    state = (0.25, 2e-13, -0.005)
    stop = plan_stop(state, lim.decel, 0, lim.scurve, creep=0.0, speed=lim.speed)
    check_continuity(stop, [lim])
    check_limits(stop, [lim], jerk_over=state[2] ** 2 / (2.0 * abs(state[1])))
    assert stop.velocity_at(stop.end_ns) == 0.0
    assert abs(stop.final_position - 0.25) < 1e-12
