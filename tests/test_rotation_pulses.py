"""Rotation pulse output (cml-users-guide.txt 5.2; ch. 3 K24, K33, K34=7) and the
in-position pulse in merge motion (ch. 3 K34=6, K73).

The golden transcripts tests/transcripts/5.2-*.cml cover ?50/?51 at rest; these
tests check the solved edge times against the actual trajectory.
"""

from __future__ import annotations

import math
from bisect import bisect_right

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coolmuscle.chain.daisy import Chain
from coolmuscle.sim.kernel import NS_PER_S, seconds
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory, new_chain


def _pulses(k34: int, *, k24: int = 1000, k37: int = 3) -> list[str]:
    """The setup of rotation pulses: resolution K37, pulses per turn K24, K34 output."""
    return [f"K37.1={k37}", f"K24.1={k24}", f"K34.1={k34}"]


def _move(chain: Chain, target: int, s: int = 50, a: int = 100) -> None:
    chain.execute(f"S.1={s}, A.1={a}, P.1={target}")
    chain.execute("^.1")
    chain.kernel.run_until(lambda: not chain.motors[1].axis.moving, seconds(60))
    chain.kernel.advance(seconds(0.05))


def _ab(chain: Chain, t: int) -> tuple[bool, bool]:
    bits = chain.motors[1].pulses.signals_at(t)
    return bits[1], bits[2]


def test_5_2_quadrature_a_leads_b_going_cw_and_lags_going_ccw(make_chain: ChainFactory) -> None:
    """K34=77: outputs 1 and 2 are A and B, 90° apart (ch. 3 K24 "quadrature")."""
    chain = make_chain(setup=_pulses(77), traced=True)
    motor = chain.motors[1]
    assert motor.pulses.quadrature()
    _move(chain, 3000)
    mid = chain.kernel.now
    _move(chain, 0)
    edges = motor.pulses.edge_times(0, chain.kernel.now)
    cw = [_ab(chain, t) for t in edges if t < mid]
    ccw = [_ab(chain, t) for t in edges if t > mid]
    assert cw[:5] == [(True, True), (False, True), (False, False), (True, False), (True, True)]
    assert ccw[:4] == [(False, True), (True, True), (True, False), (False, False)]
    # one edge per quarter passed: 250 .. 2750 (3000 and 0 are approached, never passed)
    assert len(cw) == len(ccw) == 3000 // 250 - 1


def test_5_2_single_output_switches_every_half_period(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=_pulses(7, k24=400), traced=True)
    motor = chain.motors[1]
    _move(chain, 2000)
    edges = motor.pulses.edge_times(0, chain.kernel.now)
    assert len(edges) == 2000 // 200 - 1            # 200, 400, .. 1800 (2000 not passed)
    states = [motor.pulses.signals_at(t)[1] for t in edges]
    assert states == [False, True] * 4 + [False]
    gaps = {round((b - a) / 1e3) for a, b in zip(edges[2:-3], edges[3:-2])}
    assert gaps == {40_000}                          # 200 pulses at 5000 pps: 40 ms


def test_5_2_edges_sit_exactly_on_boundary_plus_hysteresis(make_chain: ChainFactory) -> None:
    """Each edge is the instant the actual position is one hysteresis past a quarter."""
    # 50000 ppr: h = 10 pulses
    chain = make_chain(setup=_pulses(77, k24=1000, k37=10), traced=True)
    motor = chain.motors[1]
    _move(chain, 4000)
    _move(chain, 1000)
    h = motor.pulses.hysteresis()
    assert h == 10.0
    for t in motor.pulses.edge_times(0, chain.kernel.now):
        x = record(chain).sample(1, t).position
        before = record(chain).sample(1, t - 1).position
        going_up = x > before
        boundary = x - h if going_up else x + h
        assert abs(boundary / 250 - round(boundary / 250)) < 1e-6, (t, x)
        assert _ab(chain, t) != _ab(chain, t - 1)


def _actual(chain: Chain, t: int) -> float:
    """The actual user position at ``t`` from the axis history (what the trace samples)."""
    history = chain.motors[1].axis.history or []
    i = max(bisect_right([h[0] for h in history], t) - 1, 0)
    _, profile, tracking, zero, sign = history[i]
    return sign * (profile.position_at(t) - tracking.error_at(t) - zero)


def _relay(x: float, state: int, width: float, h: float) -> int:
    """A sample-by-sample Schmitt trigger, written independently of the model's."""
    while x >= (state + 1) * width + h:
        state += 1
    while x <= state * width - h:
        state -= 1
    return state


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(k24=st.integers(10, 600), k37=st.sampled_from([0, 3, 7, 10, 43]),
       plan=st.lists(st.tuples(st.integers(-2000, 2000), st.integers(20, 300)),
                     min_size=1, max_size=4),
       speed=st.integers(20, 60))
def test_5_2_solved_states_agree_with_a_sampled_schmitt_trigger(
        k24: int, k37: int, plan: list[tuple[int, int]], speed: int) -> None:
    """Property: with new targets given mid-move (so the shaft reverses inside a
    trajectory), the closed-form state equals a Schmitt trigger fed with the actual
    position every 50 µs (a reversal's excursion within 50 µs is far below 1e-3 pulse)."""
    chain = new_chain(setup=_pulses(77, k24=k24, k37=k37), traced=True)
    motor = chain.motors[1]
    chain.execute(f"S.1={speed}, A.1=200")
    for target, delay_ms in plan:
        chain.execute(f"P.1={target}")
        chain.execute("^.1")
        chain.kernel.advance(delay_ms * 1_000_000)
    chain.kernel.advance(seconds(0.3))
    h = motor.pulses.hysteresis()
    width = k24 / 4.0
    state = math.floor(_actual(chain, 0) / width)
    track = motor.pulses.track
    assert track is not None
    for t in range(0, chain.kernel.now, 50_000):
        state = _relay(_actual(chain, t), state, width, h)
        if t % 1_000_000 == 0:
            assert track.state_at(t) == state, t / NS_PER_S
    state = _relay(_actual(chain, chain.kernel.now), state, width, h)
    assert track.state() == state


def test_5_2_a_reversal_inside_one_trajectory_keeps_the_hysteresis(
        make_chain: ChainFactory) -> None:
    """A new target just before a switching point: the shaft overshoots past it and
    comes back within the hysteresis band, all in one trajectory; B stays switched."""
    # quarters of 250, h = 10: 1260 up / 1240 down
    chain = make_chain(setup=_pulses(77, k24=1000, k37=10), traced=True)
    motor = chain.motors[1]
    lim = motor.limits(10, 100)                   # 1000 pps, 5 pulses to stop
    motor.move_to([(5000.0, lim)])
    piece = motor.timeline.piece
    at = piece.first_reach(1257.0, chain.kernel.now, chain.kernel.now + seconds(5))
    assert at is not None
    chain.kernel.run(until=at)
    assert chain.execute("?52.1") == ["OUT2.1=0"]   # quarter 4: A on, B off
    motor.move_to([(1250.0, lim)])
    chain.kernel.run(until=chain.kernel.now + seconds(1))
    peak = max(_actual(chain, t) for t in range(at, chain.kernel.now, 100_000))
    assert 1260 < peak < 1268 and abs(motor.axis.position() - 1250) < 0.01
    assert chain.execute("?52.1") == ["OUT2.1=1"]   # passed 1260, never back below 1240


def test_5_2_live_reads_agree_with_the_trace(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=_pulses(77), traced=True)
    chain.execute("S.1=80, A.1=200, P.1=5000")
    chain.execute("^.1")
    live = []
    for _ in range(150):
        chain.kernel.advance(seconds(0.0073))
        live.append((chain.kernel.now, chain.execute("?50.1")[0]))
    for t, reply in live:
        a, b = _ab(chain, t)
        assert reply == f"OUT.1={a + 2 * b:02X}"


def test_5_2_pulses_cost_no_kernel_events() -> None:
    """The output is read from the position, not ticked (docs/architecture.md rule 2)."""
    counts = []
    for k34 in (0, 77):
        chain = Chain()
        chain.set_param(1, 34, k34)
        chain.execute("S.1=100, A.1=100, P.1=100000")
        start = chain.kernel.events_run
        chain.execute("^.1")
        chain.kernel.run(until=seconds(20))
        counts.append(chain.kernel.events_run - start)
    assert counts[0] == counts[1] <= 5


def test_ch3_k24_change_restarts_from_the_current_position(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=_pulses(7, k24=1000), traced=True)
    _move(chain, 700)
    assert chain.execute("?51.1") == ["OUT1.1=0"]       # 700 of 1000: second half
    chain.set_param(1, 24, 2000)
    assert chain.execute("?51.1") == ["OUT1.1=1"]       # 700 of 2000: first half
    chain.set_param(1, 34, 3)
    assert chain.motors[1].pulses.track is None
    assert chain.execute("?51.1") == ["OUT1.1=0"]


def test_5_2_reverse_coordinates_follow_the_user_position(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=_pulses(7, k24=1000), traced=True)
    motor = chain.motors[1]
    motor.axis.sign = -1                  # reverse coordinates (K45 first digit 2/3)
    motor.axis.hold_here()
    _move(chain, 250)
    assert motor.position() == 250
    assert chain.execute("?51.1") == ["OUT1.1=1"]
    chain.execute("|2.1")                 # position counter reset: re-initialised, no edge
    _move(chain, -300)
    assert chain.execute("?51.1") == ["OUT1.1=0"]


def test_ch3_k73_merge_pulse_is_on_for_k73_ms_from_each_passing_point() -> None:
    """K34=6: the output goes on at each passing point (not the start or the end) for
    K73 ms; the falling edge is an event the trace records at its exact instant."""
    chain = Chain()
    chain.set_param(1, 34, 6)
    chain.set_param(1, 73, 30)
    rec = record(chain)
    motor = chain.motors[1]
    lim = motor.limits(100, 100)
    motor.move_to([(2000.0, lim), (5000.0, lim), (9000.0, lim)])
    passing = [t for t, _ in motor.axis.profile.passing_times_ns()]
    assert len(passing) == 2
    chain.kernel.run(until=seconds(3))
    for t in passing:
        assert rec.sample(1, t - 1).outputs & 1 == 0
        assert rec.sample(1, t).outputs & 1 == 1
        assert rec.sample(1, t + 30_000_000 - 1).outputs & 1 == 1
        assert rec.sample(1, t + 30_000_000).outputs & 1 == 0
    assert math.isclose(motor.position(), 9000, abs_tol=0.5)


def test_cm1_k34_7_quadrature_with_the_k54_offset() -> None:
    """CM1 (Appendix A): K34 7 = quadrature phase output every K24 pulses, shifted by
    K54 "Quadrature output offset"."""
    chain = Chain(firmware="cm1")
    chain.execute("(.1")
    chain.set_param(1, 24, 1000)
    chain.set_param(1, 34, 77)
    chain.set_param(1, 54, 300)
    chain.execute("S.1=10, A.1=100, P.1=250")
    chain.execute("^.1")
    pulses = chain.motors[1].pulses
    chain.kernel.run(until=seconds(1))
    assert (pulses.signal(1), pulses.signal(2)) == (False, False)   # 250 - 300: last quarter
    chain.execute("P.1=400")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(2))
    assert (pulses.signal(1), pulses.signal(2)) == (True, False)    # 100: first quarter
    assert chain.execute("?50.1") == ["OUT.1=01"]        # K33=0, "Normally open": as the signal
