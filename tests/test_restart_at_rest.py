"""A reversal after an early in-position, solved from the command's end.

Ch. 3 K55: in position may come before the command ends; a bank's next move then
starts while the command still decelerates.  The planner stops that command and starts
the reversal from rest at its end (planner: "a change of direction is a stop followed
by a new start"), so ``Axis.move`` keeps the shaft's solved motion until then and
solves the new move from there (``Motion.continued``).  Against the exact oracle
(``restart_at_rest = False``: the whole motion solved from the decelerating command at
once), on twin chains: the same reports within a nanosecond, the shaft the same up
to a shift of 2 ns at every sample, and every repeat of a cycle reusing its solved motions.
"""

from __future__ import annotations

from hypothesis import example, given, settings
from hypothesis import strategies as st

from coolmuscle.chain.daisy import Chain
from coolmuscle.motor.motion.planner import Limits, plan_moves
from coolmuscle.motor.motion.profile import stops_then_restarts
from coolmuscle.sim.kernel import NS_PER_MS, seconds


def twin(exact: bool, lines: list[str]) -> tuple[Chain, list[tuple[int, str]]]:
    chain = Chain()
    chain.motors[1].axis.restart_at_rest = not exact
    events: list[tuple[int, str]] = []
    chain.subscribe(lambda e: events.append((e.time, e.text)))
    chain.execute("K23.1=1")                  # Ux reports: in position (Ux.1=8)
    for line in lines:
        chain.execute(line)
    return chain, events


Sample = tuple[float, float, float, float]


def sample(chain: Chain) -> Sample:
    """Position, speed, Pe and the size of the acceleration (pps/s, from the closed-form
    speed 1 us either side) of the shaft now."""
    axis = chain.motors[1].axis
    now = chain.kernel.now
    accel = (axis.motion.velocity_at(now + 1000) - axis.motion.velocity_at(now - 1000)) / 2e-6
    return axis.raw_actual(), axis.raw_velocity(), axis.position_error(), abs(accel)


def close(a: list[Sample], b: list[Sample], shift_ns: float = 2.0) -> bool:
    """The same motion up to a time shift of ``shift_ns``: position and Pe within 1e-4
    pulse plus the shift at the speed, speed within 0.01 pps and 1e-7 of itself (a free
    shaft under a load may run at 10^5 pps) plus the shift at the acceleration."""
    shift = shift_ns * 1e-9
    return len(a) == len(b) and all(
        abs(p - q) <= 1e-4 + shift * max(abs(v), abs(w))
        and abs(e - f) <= 1e-4 + shift * max(abs(v), abs(w))
        and abs(v - w) <= 1e-2 + 1e-7 * max(abs(v), abs(w)) + shift * max(g, h)
        for (p, v, e, g), (q, w, f, h) in zip(a, b))


Run = tuple[list[str], list[int], list[Sample]]


def run_twins(bank: list[str], samples: int, step_ms: int, load: int = 0) -> list[Run]:
    """``bank`` started on the exact chain, then on the spliced one (an overload of
    ``load`` % on each): what each printed, when, and the shaft every ``step_ms``."""
    runs = []
    for exact in (True, False):
        chain, events = twin(exact, bank)
        if load:
            chain.inject_fault(1, "overload", torque=load)
        chain.execute("[1.1")
        shaft = []
        for _ in range(samples):
            chain.kernel.advance(step_ms * NS_PER_MS)
            shaft.append(sample(chain))
        runs.append(([text for _, text in events], [t for t, _ in events], shaft))
    return runs


def assert_same_run(runs: list[Run]) -> None:
    """The spliced run is the exact one: the same report texts; each report within
    2 ns plus 1 ns for every report before it, the shaft within the run's whole shift.
    A reversal starts at the command's end rounded to the nanosecond (up to 0.5 ns from
    the planner's float end), and an instant found on the motion after it (in position,
    an alarm) rounds up to the next nanosecond; in a repeated cycle the end's rounding
    has the same sign every time, so the shift adds up along the run (hypothesis found
    5 ns after 9 reversals at K69=100, S=54, A=5 over 200 pulses; docs/fidelity.md)."""
    (texts0, times0, shaft0), (texts1, times1, shaft1) = runs
    assert texts1 == texts0
    assert all(abs(x - y) <= 2 + i for i, (x, y) in enumerate(zip(times1, times0))), \
        [x - y for x, y in zip(times1, times0)]
    assert close(shaft1, shaft0, 2 + len(times0))


@settings(max_examples=30, deadline=None)
@given(p1=st.integers(500, 30_000), p2=st.integers(-30_000, 400), s=st.integers(20, 300),
       a=st.integers(5, 300), k55=st.integers(1, 60), limit=st.integers(20, 100),
       load=st.integers(0, 100))
@example(p1=500, p2=46, s=89, a=208, k55=3, limit=20, load=0)
def test_ch3_k55_a_bank_reversing_at_in_position_moves_as_the_exact_model(
        p1: int, p2: int, s: int, a: int, k55: int, limit: int, load: int) -> None:
    """A PTP bank looping between two points (2.1, 4.1.1), an in-position window that
    comes early, a torque limit and a load torque.  (Hypothesis found the speed 0.0104
    pps apart after 106 reports, 51 ns apart, at about 204,000 pps/s: the shift at the
    acceleration, which the speed's tolerance now counts.)"""
    bank = [f"K55.1={k55}, M.1={limit}", f"S1.1={s}, A1.1={a}, P1.1={p1}, P2.1={p2}",
            "B1.1", "X0", "S1.1, A1.1, P1.1", "P2.1", "X-", "END"]
    assert_same_run(run_twins(bank, 400, 25, load))


@settings(max_examples=25, deadline=None)
@given(p1=st.integers(200, 20_000), p2=st.integers(-20_000, 100), s=st.integers(20, 300),
       a=st.integers(5, 300), a2=st.integers(5, 300), k55=st.integers(1, 80),
       k69=st.sampled_from([0, 0, 100, 1024]), k51=st.sampled_from([0, 0, 1, 5]),
       k44=st.sampled_from([100, 100, 50, 300]))
def test_ch3_k69_k51_k44_s_curves_creep_and_other_decelerations_move_as_the_exact_model(
        p1: int, p2: int, s: int, a: int, a2: int, k55: int, k69: int, k51: int,
        k44: int) -> None:
    """S-curves (K69), the creep end jump (K51), a deceleration rate of its own (K44)
    and a second A for the way back (4.1.3): the splice is taken only where the plan
    stops the command as it was going to stop, and the motion is the exact one."""
    bank = [f"K55.1={k55}, K69.1={k69}, K51.1={k51}, K44.1={k44}",
            f"S1.1={s}, A1.1={a}, P1.1={p1}, A2.1={a2}, P2.1={p2}",
            "B1.1", "X0", "S1.1, A1.1, P1.1", "A2.1, P2.1", "X-", "END"]
    assert_same_run(run_twins(bank, 300, 30))


def test_a_repeated_cycle_reuses_its_solved_moves() -> None:
    """Motor ID1 at S = 101 (bench/speed_worker.py): every move solved afresh in the
    exact model, every repeat reused once the cycle repeats."""
    bank = ["S1.1=101, A1.1=100, P1.1=10000, P2.1=0", "B1.1", "X0", "S1.1, A1.1, P1.1",
            "P2.1", "X-", "END"]
    counts = []
    for exact in (True, False):
        chain, events = twin(exact, bank)
        chain.execute("[1.1")
        chain.kernel.run(until=seconds(5))
        chain.motion_memos.clear()
        before = len(events)
        chain.kernel.run(until=seconds(125))
        counts.append((chain.motion_memos.reuse(), len(events) - before))
    ((reused0, solved0), moves0), ((reused1, solved1), moves1) = counts
    assert moves0 == moves1 > 100
    assert solved0 >= moves0 - 2 and reused0 <= 2                # each move solved afresh
    assert solved1 <= 8 and reused1 >= moves1 - 8                # each repeat reused


def test_stops_then_restarts_only_for_the_planners_stop_then_start() -> None:
    """The splice is taken only where the new plan runs the old command to its end."""
    lim = Limits(10_000.0, 100_000.0, 100_000.0)
    old = plan_moves((0.0, 0.0, 0.0), [_wp(10_000.0, lim)], 0)
    mid = old.end_ns - 5 * NS_PER_MS                              # decelerating
    back = plan_moves(old.state_at(mid), [_wp(0.0, lim)], mid)
    on = plan_moves(old.state_at(mid), [_wp(20_000.0, lim)], mid)
    softer = plan_moves(old.state_at(mid), [_wp(0.0, Limits(10_000.0, 100_000.0, 50_000.0))],
                        mid)
    assert stops_then_restarts(old, back)                         # reversal, same decel
    assert not stops_then_restarts(old, on)                       # goes on: no stop
    assert not stops_then_restarts(old, softer)                   # stops more gently
    after = plan_moves(old.state_at(old.end_ns), [_wp(0.0, lim)], old.end_ns)
    assert not stops_then_restarts(old, after)                    # the old one has ended


def _wp(target: float, lim: Limits):  # noqa: ANN202
    from coolmuscle.motor.motion.planner import Waypoint
    return Waypoint(target, lim)


def _cycle(fresh: bool, speeds: tuple[int, ...], k55: int) -> tuple[list[tuple[int, str]],
                                                                     list[float]]:
    """Motors looping PTP banks at ``speeds`` for 60 s: what they printed and when, and
    every shaft every 7 ms; ``fresh``: every plan, solved or spliced motion forgotten after
    each trajectory change, so that each is computed afresh."""
    chain = Chain(motors=len(speeds))
    events: list[tuple[int, str]] = []
    chain.subscribe(lambda e: events.append((e.time, e.text)))
    for n, s in enumerate(speeds, 1):
        if fresh:
            chain.motors[n].axis.trajectory_listeners.append(chain.motion_memos.clear)
        for line in (f"K23.{n}=1, K55.{n}={k55}",
                     f"S1.{n}={s}, A1.{n}=100, P1.{n}=10000, P2.{n}=0", f"B1.{n}", "X0",
                     f"S1.{n}, A1.{n}, P1.{n}", f"P2.{n}", "X-", "END"):
            chain.execute(line)
    for n in range(1, len(speeds) + 1):
        chain.execute(f"[1.{n}")
    shaft: list[float] = []
    for _ in range(60_000 // 7):
        chain.kernel.advance(7 * NS_PER_MS)
        for motor in chain.motors.values():
            axis = motor.axis
            shaft += [axis.raw_actual(), axis.raw_velocity(), axis.position_error()]
    return events, shaft


@settings(max_examples=4, deadline=None)
@given(speeds=st.lists(st.integers(50, 300), min_size=1, max_size=3).map(tuple),
       k55=st.integers(1, 40))
@example(speeds=(101, 102), k55=5)
def test_reused_solutions_and_splices_are_the_fresh_ones_to_the_bit(
        speeds: tuple[int, ...], k55: int) -> None:
    """docs/performance.md: the plans and solved motions (``dynamics.MotionMemos``) and the
    splices of a repeated reversal (``Motion.continued``) reused by a cycle
    are what computing them afresh gives: the same reports at the same instants and the
    same shaft, bit for bit."""
    assert _cycle(False, speeds, k55) == _cycle(True, speeds, k55)
