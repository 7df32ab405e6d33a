"""Ladder benchmark: simulated time / wall time with a ladder scanned beside a program bank.

Run: ``PYTHONPATH=src python bench/bench_ladder.py [SECONDS] [REPEATS]`` (a few seconds).

A 10-step ladder bank at K63 = 1 ms (cml-users-guide.txt ch. 3 K63; 10 steps of 250 µs,
cm-banks-rt3.txt 3.4, so it is scanned every 2.5 ms) runs beside a program bank that
moves point to point forever (X0 loop of two P lines).  The ratio of virtual seconds to
wall seconds is printed for the best of REPEATS runs (and the CPU-time ratio, which a
loaded machine does not disturb).  Goal: at least 200x real time.

The ladder bank (10 steps: L1.1 1, 3, 2 + 1, 3):
    V1.1=V1.1+V2.1;             counter
    V1.1>V3.1, V1.1=V4.1, T0.1; wrap round
    V6.1=V5.1/V2.1;             V5 is bound to "Px": read the live position
"""

from __future__ import annotations

import sys
import time

from coolmuscle.chain.daisy import Chain
from coolmuscle.sim.kernel import seconds

SETUP = ("K63.1=1", "V1.1=0", "V2.1=1", "V3.1=100000", "V4.1=0", 'V5.1="Px"',
         "S1.1=100", "A1.1=100", "P1.1=10000", "P2.1=0",
         "L1.1", "V1.1=V1.1+V2.1;", "V1.1>V3.1, V1.1=V4.1, T0.1;", "V6.1=V5.1/V2.1;", "END",
         "B1.1", "X0.1", "S1.1, A1.1, P1.1", "P2.1", "X.1-", "END", "[L1.1", "[1.1")


def run(virtual_s: float) -> tuple[float, float, int, int, int]:
    """One run: (wall s, cpu s, ladder scans, program moves, kernel events)."""
    chain = Chain()
    moves = [0]
    chain.subscribe(lambda e: moves.__setitem__(0, moves[0] + (e.text == "Ux.1=8")))
    for line in SETUP:
        chain.execute(line)
    assert chain.motors[1].banks.used() == 11   # CM2 commands; 10 RT3 steps + header
    wall, cpu = time.perf_counter(), time.process_time()
    events = chain.kernel.run(until=seconds(virtual_s))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return wall, cpu, chain.motors[1].ladder.scans, moves[0], events


def main() -> None:
    virtual_s = float(sys.argv[1]) if len(sys.argv) > 1 else 20.0
    repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 15
    results = [run(virtual_s) for _ in range(repeats)]
    wall = min(r[0] for r in results)
    cpu = min(r[1] for r in results)
    _, _, scans, moves, events = results[0]
    period_ms = virtual_s * 1000 / max(scans - 1, 1)
    print(f"virtual time      {virtual_s:.1f} s")
    print(f"ladder scans      {scans} (every {period_ms:.3f} ms: max(K63 = 1 ms, 10 x 0.25 ms))")
    print(f"program moves     {moves}")
    print(f"kernel events     {events}")
    print(f"wall time         {wall:.3f} s (best of {repeats})")
    print(f"simulated/wall    {virtual_s / wall:.0f}x real time (goal >= 200x)")
    print(f"simulated/cpu     {virtual_s / cpu:.0f}x")


if __name__ == "__main__":
    main()
