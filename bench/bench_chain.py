"""Chain benchmark: simulated time / wall time for 1, 4 and 15 motors each looping a PTP bank.

Run: ``PYTHONPATH=src python bench/bench_chain.py [SECONDS] [REPEATS]`` (a few seconds).

Every motor of the chain runs its own program bank forever (cml-users-guide.txt 2.2.2
"X0" loops without end; 4.1.1 point to point), the move of bench/bench_ladder.py
(10,000 pulses, A = 100), each motor a little faster than the one before so that their
events interleave in the one kernel instead of falling on the same instants:

    B1.n
    X0
    S1.n, A1.n, P1.n        to 10,000 pulses at S1.n = 100 + n (10,100 .. 11,500 pps)
    P2.n                    back to 0
    X-
    END

The ratio of virtual seconds to wall seconds is printed for each chain size (best of
REPEATS runs), with the wall time per move and per motor-second: the cost grows no
faster than the number of motors when those stay flat.  Goal: at least 500x real time
with 15 motors.
"""

from __future__ import annotations

import sys
import time

from speed_worker import build  # the chain of PTP banks bench_speed.py measures too

from coolmuscle.sim.kernel import seconds

SIZES = (1, 4, 15)
GOAL = 500.0


def run(motors: int, virtual_s: float) -> tuple[float, float, int, int]:
    """One run: (wall s, cpu s, moves, kernel events)."""
    chain, moves = build(motors, 1)         # motor n at S = 100 + n
    wall, cpu = time.perf_counter(), time.process_time()
    events = chain.kernel.run(until=seconds(virtual_s))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    for motor in chain.motors.values():   # the banks really ran to the end of the time
        assert motor.program.active, f"bank of ID{motor.id} stopped"
    return wall, cpu, moves[0], events


def main() -> None:
    virtual_s = float(sys.argv[1]) if len(sys.argv) > 1 else 60.0
    repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 7
    print(f"virtual time {virtual_s:.0f} s per run, best of {repeats}")
    print(f"{'motors':>6} {'moves':>7} {'events':>8} {'wall s':>8} {'sim/wall':>9} "
          f"{'sim/cpu':>8} {'us/move':>8} {'ms per motor-s':>15}")
    ratios: dict[int, float] = {}
    per_motor: dict[int, float] = {}
    for motors in SIZES:
        results = [run(motors, virtual_s) for _ in range(repeats)]
        wall = min(r[0] for r in results)
        cpu = min(r[1] for r in results)
        _, _, moves, events = results[0]
        ratios[motors] = virtual_s / wall
        per_motor_ms = wall / (motors * virtual_s) * 1000
        per_motor[motors] = per_motor_ms
        print(f"{motors:>6} {moves:>7} {events:>8} {wall:>8.3f} {virtual_s / wall:>8.0f}x "
              f"{virtual_s / cpu:>7.0f}x {wall / moves * 1e6:>8.1f} {per_motor_ms:>15.4f}")
    verdict = "ok" if ratios[SIZES[-1]] >= GOAL else "BELOW GOAL"
    growth = per_motor[SIZES[-1]] / per_motor[SIZES[0]]
    print(f"{SIZES[-1]} motors: {ratios[SIZES[-1]]:.0f}x real time (goal >= {GOAL:.0f}x): "
          f"{verdict}; wall time per motor-second x{growth:.2f} from {SIZES[0]} to "
          f"{SIZES[-1]} motors (1.00 = cost proportional to the motors)")


if __name__ == "__main__":
    main()
