"""Planner unit tests with hand-computed numbers (cml-users-guide.txt 2.1, 4.1, ch. 3)."""

from __future__ import annotations

import math

import pytest

from coolmuscle.motor.motion.planner import (
    ESTOP_DECEL,
    Limits,
    Waypoint,
    limits_from_data,
    minimum_time,
    plan_emergency_stop,
    plan_moves,
    plan_stop,
    plan_velocity,
    scurve_jerk,
)

NS = 1_000_000_000
MS = 1_000_000
T0 = 2 * NS
REST = (0.0, 0.0, 0.0)


def data(s: int = 100, a: int = 100, *, k37: int = 3, k44: int = 100, k51: int = 0,
         k69: int = 0, decel_a: int | None = None) -> Limits:
    return limits_from_data(s, a, k37=k37, k44=k44, k51=k51, k69=k69,
                            decel_a_value=decel_a)


# -- data to limits ---------------------------------------------------------------------
def test_2_1_operation_example() -> None:
    """S=100, A=100, P=10000 at K37=3: 10000 pps, 100 kpps², 0.1 s ramps, 1.1 s."""
    lim = data(100, 100)
    assert (lim.speed, lim.accel, lim.decel) == (10000.0, 100000.0, 100000.0)
    prof = plan_moves(REST, [Waypoint(10000.0, lim)], T0)
    assert prof.end_ns == T0 + 1100 * MS and minimum_time(10000, lim) == pytest.approx(1.1)
    assert prof.state_at(T0 + 50 * MS) == pytest.approx((125.0, 5000.0, 100000.0))
    assert prof.state_at(T0 + 100 * MS) == pytest.approx((500.0, 10000.0, 0.0))
    assert prof.position_at(T0 + 600 * MS) == pytest.approx(5500.0)
    assert prof.state_at(T0 + 1000 * MS) == pytest.approx((9500.0, 10000.0, -100000.0))
    assert prof.state_at(T0 + 1100 * MS) == (10000.0, 0.0, 0.0)
    assert prof.first_crossing(9500.0, T0) == T0 + 1000 * MS


def test_2_1_1_speed_unit_follows_k37() -> None:
    """"S.1=250 Set Motor 1 Speed to 25000/2500/250pps" (2.1.1)."""
    assert [data(250, k37=k).speed for k in (3, 23, 83)] == [25000.0, 2500.0, 250.0]
    assert data(-250).speed == 25000.0 and data(100, -7).accel == 7000.0


def test_k44_deceleration_ratio_and_4_1_3_second_a() -> None:
    assert data(100, 100, k44=50).decel == 50000.0
    assert data(100, 100, k44=500).decel == 500000.0
    assert data(100, 100, k44=50, decel_a=300).decel == 300000.0


def test_k51_creep_in_speed_units_clamped_to_s() -> None:
    assert data(100, k51=5).creep == 500.0
    assert data(100, k37=23, k51=5).creep == 50.0
    assert data(3, k51=1000).creep == 300.0


def test_bad_data_refused() -> None:
    for bad in (dict(s=0), dict(a=0), dict(k69=1025), dict(k69=-1)):
        with pytest.raises(ValueError):
            data(**bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        Limits(100.0, 1.0, 1.0, creep=200.0)
    with pytest.raises(ValueError):
        plan_moves(REST, [], 0)


# -- point to point ------------------------------------------------------------------------
def test_triangle_short_move_and_k44() -> None:
    lim = data(100, 100)
    prof = plan_moves(REST, [Waypoint(-400.0, lim)], T0)
    peak = math.sqrt(100000.0 * 400.0)
    assert prof.max_speed() == pytest.approx(peak)
    assert prof.duration == pytest.approx(2 * peak / 100000.0)
    fast_stop = data(100, 100, k44=300)  # D = 3A: peak² = 2AD·L/(A+D) = 1.5 A L
    prof = plan_moves(REST, [Waypoint(400.0, fast_stop)], T0)
    peak = math.sqrt(1.5 * 100000.0 * 400.0)
    assert prof.max_speed() == pytest.approx(peak)
    assert prof.duration == pytest.approx(peak / 100000.0 + peak / 300000.0)


def test_k51_creep_start_and_end_jumps() -> None:
    """Starts at 1000 pps, accelerates 0.09 s (495 pulses), same at the end."""
    lim = data(100, 100, k51=10)
    prof = plan_moves(REST, [Waypoint(10000.0, lim)], T0)
    assert prof.velocity_at(T0 - 1) == 0.0 and prof.velocity_at(T0) == 1000.0
    assert prof.position_at(T0 + 90 * MS) == pytest.approx(495.0)
    assert prof.duration == pytest.approx(0.09 + 0.901 + 0.09)
    assert prof.duration == pytest.approx(minimum_time(10000.0, lim))
    assert prof.velocity_at(prof.end_ns - 1) == pytest.approx(1000.0, abs=0.001)
    assert prof.velocity_at(prof.end_ns) == 0.0


def test_k69_full_s_curve() -> None:
    """K69=1024: J = A²/S = 1e6 pps³; accelerating to S takes 2S/A = 0.2 s."""
    lim = data(100, 100, k69=1024)
    assert lim.jerk_accel == pytest.approx(1e6)
    prof = plan_moves(REST, [Waypoint(10000.0, lim)], T0)
    assert prof.state_at(T0 + 100 * MS) == pytest.approx((1000.0 / 6.0, 5000.0, 100000.0))
    assert prof.state_at(T0 + 200 * MS) == pytest.approx((1000.0, 10000.0, 0.0))
    assert prof.duration == pytest.approx(1.2)
    assert max(abs(s.j) for s in prof.segments) == pytest.approx(1e6)


def test_k69_half_spends_half_the_acceleration_in_jerk() -> None:
    lim = data(100, 100, k69=512)
    jerk = scurve_jerk(100000.0, 10000.0, 512)
    assert jerk == pytest.approx(3e6)
    ramp, hold = 100000.0 / jerk, 10000.0 / 100000.0 - 100000.0 / jerk
    assert 2 * ramp / (2 * ramp + hold) == pytest.approx(0.5)
    prof = plan_moves(REST, [Waypoint(10000.0, lim)], 0)
    assert [s.duration for s in prof.segments[:3]] == pytest.approx([ramp, hold, ramp])
    assert scurve_jerk(1.0, 1.0, 0) == math.inf


# -- merge motion -------------------------------------------------------------------------
def test_4_1_2_speed_increase_starts_at_the_passing_point() -> None:
    slow, fast = data(50), data(100)
    prof = plan_moves(REST, [Waypoint(10000.0, slow), Waypoint(20000.0, fast)], T0)
    ((t_pass, index),) = prof.passing_times_ns()
    assert index == 0 and t_pass == T0 + 2025 * MS  # 0.05 s ramp + 9875 / 5000
    assert prof.velocity_at(t_pass) == pytest.approx(5000.0)
    assert prof.acceleration_at(t_pass) == 100000.0
    assert prof.velocity_at(t_pass + 50 * MS) == pytest.approx(10000.0)


def test_4_1_2_speed_decrease_completes_by_the_passing_point() -> None:
    fast, slow = data(100), data(50)
    prof = plan_moves(REST, [Waypoint(10000.0, fast), Waypoint(20000.0, slow)], T0)
    ((t_pass, _),) = prof.passing_times_ns()
    assert t_pass == T0 + 1062500 * 1000  # 0.1 + 0.9125 + 0.05 s
    assert prof.velocity_at(t_pass) == pytest.approx(5000.0)
    assert prof.velocity_at(t_pass - 25 * MS) == pytest.approx(7500.0)
    assert prof.position_at(t_pass) == pytest.approx(10000.0)


def test_4_1_2_reversal_stops_at_the_point() -> None:
    lim = data(100)
    prof = plan_moves(REST, [Waypoint(10000.0, lim), Waypoint(5000.0, lim)], T0)
    ((t_pass, _),) = prof.passing_times_ns()
    assert t_pass == T0 + 1100 * MS and prof.velocity_at(t_pass) == 0.0
    assert prof.duration == pytest.approx(1.1 + minimum_time(5000.0, lim))
    assert prof.final_position == 5000.0


def test_4_1_3_second_a_is_the_deceleration_into_p2() -> None:
    """S1.1, A1.1, P1.1, A2.1, P2.1: slow acceleration, quick deceleration."""
    first = data(100, 50)
    second = data(100, 50, decel_a=400)
    prof = plan_moves(REST, [Waypoint(5000.0, first), Waypoint(20000.0, second)], T0)
    assert prof.acceleration_at(T0 + MS) == 50000.0
    assert prof.acceleration_at(prof.end_ns - MS) == -400000.0
    assert prof.velocity_at(prof.passing_times_ns()[0][0]) == pytest.approx(10000.0)


def test_repeated_waypoint_passes_together() -> None:
    lim = data(100)
    pts = [Waypoint(1000.0, lim), Waypoint(1000.0, lim), Waypoint(3000.0, lim)]
    prof = plan_moves(REST, pts, T0)
    (t0, i0), (t1, i1) = prof.passing_times_ns()
    assert (i0, i1) == (0, 1) and t0 == t1 and prof.velocity_at(t0) > 0.0


def test_target_where_we_stand_is_an_empty_move() -> None:
    prof = plan_moves((7.0, 0.0, 0.0), [Waypoint(7.0, data())], T0)
    assert prof.segments == () and prof.end_ns == T0 and prof.final_position == 7.0


# -- re-planning ---------------------------------------------------------------------------
def test_new_target_too_close_goes_past_and_comes_back() -> None:
    """At 10000 pps, stopping takes 500 pulses: a target 100 ahead is overshot."""
    lim = data(100)
    prof = plan_moves((0.0, 10000.0, 0.0), [Waypoint(100.0, lim)], T0)
    assert prof.position_at(T0 + 100 * MS) == pytest.approx(500.0)
    assert prof.velocity_at(T0 + 100 * MS) == 0.0
    first = prof.first_crossing(100.0, T0)
    again = prof.first_crossing(100.0, first + MS)
    assert first == T0 + round((0.1 - math.sqrt(0.008)) * NS)
    assert abs(again - prof.end_ns) <= 1 and prof.final_position == 100.0


def test_lower_speed_while_running() -> None:
    prof = plan_moves((0.0, 10000.0, 0.0), [Waypoint(100000.0, data(50))], T0)
    assert prof.state_at(T0) == (0.0, 10000.0, -100000.0)
    assert prof.velocity_at(T0 + 50 * MS) == pytest.approx(5000.0)
    assert prof.duration == pytest.approx(0.05 + (100000.0 - 375.0 - 125.0) / 5000.0 + 0.05)


def test_moving_away_stops_then_returns() -> None:
    lim = data(100)
    prof = plan_moves((0.0, -10000.0, 0.0), [Waypoint(1000.0, lim)], T0)
    assert prof.position_at(T0 + 100 * MS) == pytest.approx(-500.0)
    assert prof.duration == pytest.approx(0.1 + minimum_time(1500.0, lim))


# -- continuous rotation and stops -----------------------------------------------------------
def test_2_1_1_continuous_rotation() -> None:
    lim = data(100)
    run = plan_velocity(REST, 10000.0, lim, T0)
    assert run.end_ns is None and run.final_position == math.inf
    assert run.position_at(T0 + 10 * NS) == pytest.approx(500.0 + 9.9 * 10000.0)
    assert run.velocity_at(T0 + 10**5 * NS) == 10000.0


def test_continuous_rotation_reverses_through_a_stop() -> None:
    lim = data(100)
    run = plan_velocity((0.0, 10000.0, 0.0), -5000.0, lim, T0)
    assert run.state_at(T0 + 100 * MS) == pytest.approx((500.0, 0.0, -100000.0))
    assert run.velocity_at(T0 + 150 * MS) == pytest.approx(-5000.0)
    assert run.velocity_at(T0 + 151 * MS) == -5000.0
    assert run.position_at(T0 + 150 * MS) == pytest.approx(500.0 - 125.0)
    stop = plan_velocity((0.0, 10000.0, 0.0), 0.0, lim, T0)
    assert stop.final_position == pytest.approx(500.0) and stop.end_ns == T0 + 100 * MS


def test_stops() -> None:
    stop = plan_stop((10.0, 10000.0, 0.0), 100000.0, T0)
    assert stop.end_ns == T0 + 100 * MS and stop.final_position == pytest.approx(510.0)
    creep = plan_stop((0.0, -10000.0, 0.0), 100000.0, T0, creep=1000.0)
    assert creep.end_ns == T0 + 90 * MS and creep.final_position == pytest.approx(-495.0)
    smooth = plan_stop((0.0, 10000.0, 0.0), 100000.0, T0, 1024, speed=10000.0)
    assert smooth.duration == pytest.approx(0.2) and smooth.final_position == pytest.approx(1000.0)
    assert plan_stop((4.0, 0.0, 0.0), 1.0, T0).segments == ()


def test_emergency_stop_at_maximum_deceleration() -> None:
    assert ESTOP_DECEL == 32767 * 1000 * 5
    stop = plan_emergency_stop((0.0, 3_276_700.0, 0.0), T0)
    assert stop.duration == pytest.approx(3_276_700.0 / ESTOP_DECEL)
    assert stop.final_position == pytest.approx(3_276_700.0 ** 2 / (2 * ESTOP_DECEL))
