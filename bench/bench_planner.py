"""Planner benchmark: plan and evaluation rates, closed form vs 1 ms fixed-step integration.

Run: ``PYTHONPATH=src python bench/bench_planner.py`` (about 10-20 s).

1. Plan rate for point-to-point (trapezoid, S-curve), merge and re-plan moves.
2. Query rate of the closed form (``position_at``, ``state_at``, ``first_crossing``).
3. The same moves followed by a naive simulator that integrates the commanded
   acceleration every 1 ms (what a ticking model would do): time per move and final
   position error, side by side with the closed form answering the same questions
   (state at 5 instants, time the target is reached).  Printed as a ratio.
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable

from coolmuscle.motor.motion.planner import Limits, Waypoint, limits_from_data, plan_moves
from coolmuscle.motor.motion.profile import Profile

NS = 1_000_000_000
STEP_NS = 1_000_000


def _limits(rng: random.Random, k69: int) -> Limits:
    return limits_from_data(rng.randint(20, 300), rng.randint(20, 300), k37=3,
                            k44=rng.choice([100, 50, 200]), k51=rng.choice([0, 2]), k69=k69)


def _moves(rng: random.Random, count: int) -> list[tuple[str, tuple[float, float, float],
                                                         list[Waypoint]]]:
    moves = []
    for i in range(count):
        kind = ("ptp", "ptp-s", "merge-5", "replan-s")[i % 4]
        k69 = 0 if kind == "ptp" else rng.choice([0, 512, 1024])
        if kind.startswith("ptp"):
            pts = [Waypoint(rng.uniform(-50000, 50000), _limits(rng, k69 or 700))]
        elif kind == "merge-5":
            here, pts = 0.0, []
            for _ in range(5):
                here += rng.uniform(1000, 20000) * rng.choice([1, 1, -1])
                pts.append(Waypoint(here, _limits(rng, k69)))
        else:
            pts = [Waypoint(rng.uniform(-50000, 50000), _limits(rng, 1024))]
        state = (0.0, 0.0, 0.0)
        if kind == "replan-s":
            first = plan_moves(state, [Waypoint(80000.0, pts[0].limits)], 0)
            state = first.state_at(first.end_ns // 3)
        moves.append((kind, state, pts))
    return moves


def _rate(fn: Callable[[], object], n: int) -> float:
    start = time.perf_counter()
    for _ in range(n):
        fn()
    return n / (time.perf_counter() - start)


def bench_plans(moves: list) -> None:
    print("plan rate (plans/s)")
    for kind in ("ptp", "ptp-s", "merge-5", "replan-s"):
        subset = [(s, p) for k, s, p in moves if k == kind]
        start = time.perf_counter()
        for state, pts in subset:
            plan_moves(state, pts, 0)
        rate = len(subset) / (time.perf_counter() - start)
        print(f"  {kind:9s} {rate:10.0f}")


def bench_queries(profiles: list[Profile]) -> None:
    rng = random.Random(2)
    times = [(p, rng.randrange(0, p.end_ns)) for p in profiles for _ in range(20)]
    print("query rate (calls/s)")
    for name, call in (("position_at", lambda p, t: p.position_at(t)),
                       ("state_at", lambda p, t: p.state_at(t)),
                       ("first_crossing", lambda p, t: p.first_crossing(p.final_position, t))):
        start = time.perf_counter()
        for prof, t in times:
            call(prof, t)
        print(f"  {name:15s} {len(times) / (time.perf_counter() - start):12.0f}")


def _naive(prof: Profile, target: float) -> tuple[float, int | None]:
    """1 ms Euler integration of the commanded acceleration (velocity jumps from the
    profile, as a ticking model would apply them); returns final position and the
    first tick at which the target is reached."""
    p, v = prof.start_state[0], prof.start_state[1]
    reached, side = None, p - target
    t = prof.origin_ns
    while t < prof.end_ns:
        a = prof.acceleration_at(t)
        v_cmd = prof.velocity_at(t)
        if abs(v_cmd - v) > 1.0:  # creep jumps
            v = v_cmd
        p += v * 1e-3 + a * 5e-7
        v += a * 1e-3
        t += STEP_NS
        if reached is None and (p - target) * side <= 0.0:
            reached = t
    return p, reached


def _closed(prof: Profile, target: float) -> tuple[float, int | None]:
    span = prof.end_ns - prof.origin_ns
    for k in range(5):
        prof.state_at(prof.origin_ns + span * k // 4)
    return prof.position_at(prof.end_ns), prof.first_crossing(target, prof.origin_ns)


def bench_naive(profiles: list[Profile]) -> None:
    total_ticks = sum((p.end_ns - p.origin_ns) // STEP_NS for p in profiles)
    start = time.perf_counter()
    worst = 0.0
    for prof in profiles:
        final, _ = _naive(prof, prof.final_position)
        worst = max(worst, abs(final - prof.final_position))
    naive = time.perf_counter() - start
    start = time.perf_counter()
    for prof in profiles:
        _closed(prof, prof.final_position)
    closed = time.perf_counter() - start
    n = len(profiles)
    print(f"closed form vs 1 ms fixed-step integration ({n} moves, {total_ticks} ticks)")
    print(f"  {'':22s} {'closed form':>14s} {'1 ms steps':>14s} {'ratio':>8s}")
    print(f"  {'time per move (us)':22s} {closed / n * 1e6:14.1f} {naive / n * 1e6:14.1f} "
          f"{naive / closed:8.0f}x")
    print(f"  {'worst final error':22s} {0.0:14.2e} {worst:14.2e}   (pulses)")


def main() -> None:
    rng = random.Random(1)
    moves = _moves(rng, 2000)
    bench_plans(moves)
    profiles = [plan_moves(s, p, 0) for _, s, p in moves]
    profiles = [p for p in profiles if p.end_ns and p.end_ns > 0]
    bench_queries(profiles)
    bench_naive(profiles[:300])


if __name__ == "__main__":
    main()
