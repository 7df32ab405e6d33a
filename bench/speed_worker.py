"""One measurement of bench/bench_speed.py, run in a fresh interpreter.

Run: ``PYTHONPATH=TREE/src python bench/speed_worker.py ROW [ARGS]``; prints one JSON
object.  It uses only what every version of coolmuscle since the architecture refactor
offers (``Chain``, ``Chain.target_stream``, the kernel), so the same file measures
today's tree and a baseline tree side by side (bench_speed.py ``--baseline``).

Rows:

* ``moves SECONDS``: one motor looping a PTP bank (1.1 s moves), in process: wall and
  CPU per move, kernel events per move, Python function calls per move (counted with
  ``sys.setprofile`` over a separate short run, so the timing is not disturbed).
* ``chain MOTORS SECONDS``: bench_chain.py's chain, each motor looping its bank.
* ``stream MOTORS CYCLES``: ``target_stream`` on every motor, a new csp target every
  1 ms (a cosine ramp of 4,000 pulses in 2 s and back, each motor's a little longer
  than the one before: every cycle of every axis differs from every other, so no
  solved motion is reused), wall and CPU per axis-cycle.
"""

from __future__ import annotations

import json
import math
import sys
import time

from coolmuscle.chain.daisy import Chain

NS_PER_S = 1_000_000_000
NS_PER_MS = 1_000_000

#: The PTP bank of the issue's first row: 10,000 pulses at S=100, A=100 (1.1 s a move).
BANK = ("S1.{n}={s}, A1.{n}=100, P1.{n}=10000, P2.{n}=0", "B1.{n}", "X0",
        "S1.{n}, A1.{n}, P1.{n}", "P2.{n}", "X-", "END")


def build(motors: int, speed_step: int) -> tuple[Chain, list[int]]:
    """A chain whose every motor loops BANK (motor n at S = 100 + n * speed_step)."""
    chain = Chain(motors=motors)
    moves = [0]

    def count(event: object) -> None:
        if getattr(event, "kind", None) == "status":
            moves[0] += 1
    chain.subscribe(count)
    for n in range(1, motors + 1):
        for line in BANK:
            chain.execute(line.format(n=n, s=100 + n * speed_step))
    for n in range(1, motors + 1):
        chain.execute(f"[1.{n}")
    return chain, moves


def count_calls(run: object) -> int:
    """Python function calls made by ``run()`` (sys.setprofile 'call' events)."""
    calls = [0]

    def profiler(frame: object, event: str, arg: object) -> None:
        if event == "call":
            calls[0] += 1
    sys.setprofile(profiler)
    try:
        run()  # type: ignore[operator]
    finally:
        sys.setprofile(None)
    return calls[0]


def row_moves(virtual_s: float) -> dict[str, float]:
    chain, moves = build(1, 0)
    chain.kernel.run(until=NS_PER_S)            # the first move under way
    m0, e0 = moves[0], chain.kernel.events_run
    wall, cpu = time.perf_counter(), time.process_time()
    chain.kernel.run(until=round((1 + virtual_s) * NS_PER_S))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    n = moves[0] - m0
    events = (chain.kernel.events_run - e0) / n
    m1 = moves[0]
    end = chain.kernel.now + 20 * NS_PER_S
    calls = count_calls(lambda: chain.kernel.run(until=end))
    return {"wall": wall, "cpu": cpu, "moves": n, "us_per_move": wall / n * 1e6,
            "cpu_us_per_move": cpu / n * 1e6, "events_per_move": events,
            "calls_per_move": calls / (moves[0] - m1), "ratio": virtual_s / wall}


def row_chain(motors: int, virtual_s: float) -> dict[str, float]:
    chain, moves = build(motors, 1)
    wall, cpu = time.perf_counter(), time.process_time()
    events = chain.kernel.run(until=round(virtual_s * NS_PER_S))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return {"wall": wall, "cpu": cpu, "moves": moves[0], "events": events,
            "ratio": virtual_s / wall, "us_per_move": wall / max(moves[0], 1) * 1e6}


def ramp(i: int, n: int = 1) -> int:
    """Motor ``n``'s csp target of cycle ``i``: 0 -> 4,000 (+ 100 n) -> 0 pulses, 2 s
    each way (cosine)."""
    half = 2000.0 + 50.0 * n
    return round(half - half * math.cos(2.0 * math.pi * i / 4000.0))


def row_stream(motors: int, cycles: int) -> dict[str, float]:
    chain = Chain(motors=motors)
    streams = [chain.target_stream(n) for n in range(1, motors + 1)]
    kernel = chain.kernel
    lag = 0.0

    def go(first: int, last: int) -> None:
        nonlocal lag
        for i in range(first, last):
            for n, stream in enumerate(streams, 1):
                stream.push(ramp(i, n))
            kernel.advance(NS_PER_MS)
            lag = max(lag, abs(chain.motors[1].axis.position_error()))
    wall, cpu = time.perf_counter(), time.process_time()
    go(0, cycles)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    calls = count_calls(lambda: go(cycles, cycles + 200))
    axis_cycles = cycles * motors
    return {"wall": wall, "cpu": cpu, "us_per_axis_cycle": wall / axis_cycles * 1e6,
            "cpu_us_per_axis_cycle": cpu / axis_cycles * 1e6,
            "calls_per_axis_cycle": calls / (200 * motors), "max_lag": lag,
            "events_per_axis_cycle": kernel.events_run / ((cycles + 200) * motors)}


def main(argv: list[str]) -> None:
    row, args = argv[0], argv[1:]
    if row == "moves":
        out = row_moves(float(args[0]))
    elif row == "chain":
        out = row_chain(int(args[0]), float(args[1]))
    elif row == "stream":
        out = row_stream(int(args[0]), int(args[1]))
    else:
        raise SystemExit(f"unknown row {row!r}")
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1:])
