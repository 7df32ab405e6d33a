"""A followed target's motion built to a horizon (issue 12 item 9, docs/performance.md).

``Axis.follow`` (csp 6.3, ``Dx``) builds the shaft's motion only up to the first piece
that ends two target intervals ahead, and extends it there when no new target came.
The exact model builds the whole motion at once (``follow_horizon_ns = None``).  Both
run on twin chains: the same shaft at every instant, the same reports at the same
instants, and the same pieces once a horizon's motion is extended.
"""

from __future__ import annotations

from hypothesis import given, settings, strategies as st

from coolmuscle.chain.daisy import Chain
from coolmuscle.motor.motion.dynamics import Drive, Motion
from coolmuscle.motor.motion.profile import hold
from coolmuscle.sim.kernel import NS_PER_MS, seconds


def twin(exact: bool, setup: str) -> tuple[Chain, list[tuple[int, str]]]:
    chain = Chain()
    if exact:
        chain.motors[1].axis.follow_horizon_ns = None
    events: list[tuple[int, str]] = []
    chain.subscribe(lambda e: events.append((e.time, e.text)))
    chain.execute("K23.1=1")                 # motion-done reports: Ux.1=8 at in-position
    chain.execute(setup)
    return chain, events


def shaft(chain: Chain) -> tuple[float, float, float, float, int]:
    motor = chain.motors[1]
    axis = motor.axis
    return (axis.raw_actual(), axis.raw_velocity(), axis.position_error(),
            axis.torque_percent(), motor.alarm)


streams = st.lists(st.tuples(st.integers(-20_000, 20_000), st.integers(0, 60)),
                   min_size=1, max_size=40)


@settings(max_examples=40, deadline=None)
@given(stream=streams, limit=st.integers(5, 100), k57=st.integers(1, 300),
       k55=st.integers(1, 50), stopper=st.one_of(st.none(), st.integers(300, 15_000)),
       load=st.integers(0, 150))
def test_csp_6_3_a_horizon_motion_is_the_whole_motion(
        stream: list[tuple[int, int]], limit: int, k57: int, k55: int,
        stopper: int | None, load: int) -> None:
    """Targets at random intervals (0-60 ms: many beyond the horizon, so the motion is
    extended), a torque limit, stoppers and a load torque that stall or overload it."""
    runs = []
    for exact in (True, False):
        chain, events = twin(exact, f"K57.1={k57}, K55.1={k55}, M.1={limit}")
        if stopper is not None:
            chain.motors[1].geometry.stopper_cw = float(stopper)
        if load:
            chain.inject_fault(1, "overload", torque=load)
        follow = chain.target_stream(1)
        samples = []
        for target, gap_ms in stream:
            follow.push(target)
            for _ in range(3):
                chain.kernel.advance(gap_ms * NS_PER_MS // 3 + 1)
                samples.append(shaft(chain))
        chain.kernel.advance(seconds(2))
        samples.append(shaft(chain))
        runs.append((events, samples))
    assert runs[0] == runs[1]


@settings(max_examples=40, deadline=None)
@given(start=st.floats(-5_000, 5_000), speed=st.floats(-40_000, 40_000),
       target=st.floats(-5_000, 5_000), horizon_us=st.integers(0, 30_000),
       limit=st.floats(1e4, 1e8), friction=st.floats(0.0, 5e4), load=st.floats(-5e4, 5e4))
def test_an_extended_motion_has_the_pieces_of_a_whole_build(
        start: float, speed: float, target: float, horizon_us: int, limit: float,
        friction: float, load: float) -> None:
    drive = Drive(kp=350.0, a_limit=limit, a_friction=friction, a_load=load, v_max=2e5)
    origin = 123_456_789
    whole = Motion(hold(target, origin), origin, start, speed, drive)
    part = Motion(hold(target, origin), origin, start, speed, drive,
                  horizon_ns=origin + horizon_us * 1000)
    assert whole.complete
    if not part.complete:
        until = part.built_until_ns
        assert until is not None and until >= origin + horizon_us * 1000
        assert [repr(p) for p in part.pieces] == [repr(p) for p in whole.pieces[:len(part.pieces)]]
        assert part.extend() and part.complete and part.built_until_ns is None
    assert not part.extend()
    assert [repr(p) for p in part.pieces] == [repr(p) for p in whole.pieces]
    assert {k: part.peak(k) for k in ("err", "vel", "torque")} == \
        {k: whole.peak(k) for k in ("err", "vel", "torque")}


def test_csp_6_3_a_steady_stream_never_extends_and_builds_fewer_pieces() -> None:
    """A target every 1 ms: each motion is replaced before its horizon, so no extension
    runs; the horizon motions hold fewer pieces than the whole ones."""
    counts = []
    for exact in (True, False):
        chain, _ = twin(exact, "M.1=50")
        follow = chain.target_stream(1)
        axis = chain.motors[1].axis
        pieces = 0
        for i in range(500):
            follow.push(8 * i)
            pieces += len(axis.motion.pieces)
            chain.kernel.advance(NS_PER_MS)
        counts.append((pieces, chain.kernel.events_run, axis.motion.complete))
    (whole, whole_events, whole_done), (part, part_events, part_done) = counts
    assert whole_done and not part_done
    assert part < whole
    assert part_events == whole_events


def test_csp_6_3_a_stream_that_stops_is_extended_at_its_horizon() -> None:
    """Targets every 1 ms, then none: the last motion, built to 2 ms ahead, is extended
    there (the same Motion, now whole) and the shaft settles as in the exact model,
    with the same in-position report (K23 motion-done, Ux.1=8)."""
    runs = []
    for exact in (True, False):
        chain, events = twin(exact, "M.1=40, K55.1=3")
        follow = chain.target_stream(1)
        axis = chain.motors[1].axis
        for i in range(30):
            follow.push(40 * i)
            chain.kernel.advance(NS_PER_MS)
        last = axis.motion
        built = last.built_until_ns
        samples = []
        for _ in range(60):
            chain.kernel.advance(NS_PER_MS)
            samples.append(shaft(chain))
        runs.append((events, samples, built, last.complete, axis.motion is last))
    (exact_events, exact_samples, exact_built, _, _), (events, samples, built, done, same) = runs
    assert exact_built is None and built is not None
    assert done and same
    assert events == exact_events and samples == exact_samples
    assert any(text.startswith("Ux.1=8") for _, text in events)
