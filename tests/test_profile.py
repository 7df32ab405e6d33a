"""Unit tests of closed-form profiles (coolmuscle.motor.motion.profile) with hand numbers."""

from __future__ import annotations

import math
import random

import pytest

from coolmuscle.motor.motion.profile import Profile, Segment, hold

NS = 1_000_000_000
T0 = 3 * NS  # a non-zero origin everywhere, to catch origin mistakes


def hill() -> Profile:
    """p = 10τ - 5τ² for 2 s: up to 5 at τ=1, back to 0 at τ=2."""
    return Profile(T0, [Segment(0.0, 2.0, 0.0, 10.0, -10.0, 0.0)], final_position=0.0)


def test_segment_polynomial() -> None:
    seg = Segment(1.0, 2.0, 1.0, 2.0, 6.0, 12.0)
    assert seg.end == 3.0
    assert seg.position(1.0) == 1.0 + 2.0 + 3.0 + 2.0
    assert seg.velocity(1.0) == 2.0 + 6.0 + 6.0
    assert seg.acceleration(1.0) == 18.0
    assert seg.end_state() == seg.state(2.0)


def test_before_origin_start_state_after_end_final_at_rest() -> None:
    prof = Profile(T0, [Segment(0.0, 0.5, 1.0, 4.0, 2.0, 0.0)], start_state=(1.0, 3.0, 7.0))
    assert prof.state_at(T0 - 1) == (1.0, 3.0, 7.0)
    assert prof.state_at(T0) == (1.0, 4.0, 2.0)
    assert prof.end_ns == T0 + NS // 2 and prof.duration == 0.5
    assert prof.final_position == 1.0 + 2.0 + 0.25
    assert prof.state_at(prof.end_ns) == (3.25, 0.0, 0.0)
    assert prof.position_at(prof.end_ns - NS // 4) == 1.0 + 1.0 + 0.0625


def test_evaluation_finds_the_right_segment_among_many() -> None:
    segs, p, t = [], 0.0, 0.0
    for i in range(1000):
        v = float(i % 7 - 3) or 1.0
        segs.append(Segment(t, 0.01, p, v, 0.0, 0.0))
        p, t = p + v * 0.01, t + 0.01
    prof = Profile(T0, segs)
    rng = random.Random(1)
    for _ in range(300):
        i = rng.randrange(1000)
        frac = rng.random() * 0.98 + 0.01
        t_ns = T0 + round((segs[i].start + 0.01 * frac) * NS)
        tau = (t_ns - T0) / NS - segs[i].start
        assert prof.position_at(t_ns) == pytest.approx(segs[i].p + segs[i].v * tau, abs=1e-9)
        assert prof.velocity_at(t_ns) == segs[i].v


def test_hold() -> None:
    prof = hold(12.5, T0)
    assert prof.segments == () and prof.end_ns == T0 and prof.duration == 0.0
    for t in (0, T0, T0 + NS):
        assert prof.state_at(t) == (12.5, 0.0, 0.0)
    assert prof.first_crossing(12.5, T0 + 5) == T0 + 5
    assert prof.first_crossing(12.0, 0) is None
    assert prof.time_speed_below(0.0, T0 + 7) == T0 + 7
    assert prof.max_speed() == 0.0 and prof.passing_times_ns() == []


def test_endless_constant_speed() -> None:
    prof = Profile(T0, [Segment(0.0, 0.1, 0.0, 0.0, 1000.0, 0.0),
                        Segment(0.1, math.inf, 5.0, 100.0, 0.0, 0.0)])
    assert prof.end_ns is None and prof.final_position == math.inf
    assert prof.position_at(T0 + 100 * NS) == pytest.approx(5.0 + 100.0 * 99.9)
    assert prof.velocity_at(T0 + 10**6 * NS) == 100.0
    assert prof.first_crossing(1005.0, T0) == T0 + round(10.1 * NS)
    assert prof.first_crossing(-1.0, T0) is None
    assert prof.time_speed_below(50.0, T0) == T0  # starts at rest
    assert prof.time_speed_below(50.0, T0 + NS) is None
    assert prof.max_speed() == 100.0


def test_first_crossing_non_monotonic_segment() -> None:
    prof = hill()
    assert prof.first_crossing(3.75, 0) == T0 + NS // 2
    assert prof.first_crossing(3.75, T0 + NS // 2 + 1) == T0 + 3 * NS // 2
    assert prof.first_crossing(5.0, T0) == T0 + NS  # touches at the top
    assert prof.first_crossing(5.0001, T0) is None
    assert prof.first_crossing(0.0, T0 - 10) == T0 - 10  # already there before origin
    assert prof.first_crossing(0.0, T0 + 1) == T0 + 2 * NS  # comes back at the end
    assert prof.first_crossing(0.0, T0 + 5 * NS) == T0 + 5 * NS


def test_first_crossing_cubic() -> None:
    prof = Profile(T0, [Segment(0.0, 3.0, 0.0, 0.0, 0.0, 6.0)])  # p = τ³
    assert prof.first_crossing(8.0, 0) == T0 + 2 * NS
    t = prof.first_crossing(2.0, 0)
    assert t == T0 + round(2.0 ** (1 / 3) * NS)
    assert prof.position_at(t) == pytest.approx(2.0, abs=1e-8)


def test_time_speed_below_and_max_speed() -> None:
    prof = hill()
    assert prof.time_speed_below(5.0, T0) == T0 + NS // 2
    assert prof.time_speed_below(5.0, T0 + NS) == T0 + NS
    assert prof.time_speed_below(20.0, T0) == T0
    bump = Profile(0, [Segment(0.0, 2.0, 0.0, 0.0, 10.0, -10.0)])  # v = 10τ - 5τ²
    assert bump.max_speed() == pytest.approx(5.0)
    assert bump.time_speed_below(1.0, NS // 2) == round((1.0 + math.sqrt(0.8)) * NS)


def test_passing_times() -> None:
    prof = Profile(T0, [Segment(0.0, 1.0, 0.0, 1.0, 0.0, 0.0)],
                   passing_times=[(0.25, 0), (0.5, 2)])
    assert prof.passing_times_ns() == [(T0 + NS // 4, 0), (T0 + NS // 2, 2)]
    assert prof.passing_times == ((0.25, 0), (0.5, 2))


@pytest.mark.parametrize("segments", [
    [Segment(0.0, 1.0, 0.0, 1.0, 0.0, 0.0), Segment(1.5, 1.0, 1.0, 1.0, 0.0, 0.0)],
    [Segment(0.0, 0.0, 0.0, 1.0, 0.0, 0.0)],
    [Segment(0.0, math.inf, 0.0, 1.0, 0.0, 0.0), Segment(math.inf, 1.0, 0.0, 1.0, 0.0, 0.0)],
    [Segment(0.0, math.inf, 0.0, 1.0, 1.0, 0.0)],
    [Segment(0.5, 1.0, 0.0, 1.0, 0.0, 0.0)],
])
def test_malformed_chains_are_refused(segments: list[Segment]) -> None:
    with pytest.raises(ValueError):
        Profile(0, segments)
