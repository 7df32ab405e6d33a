"""Benchmark: the user's console round trip on a real motor's line while the page polls.

``coolmuscle web PORT`` polls position, speed, torque, temperature and status at a rate
the line can carry (docs/real-motor.md "The page on a real motor"), and the user's
lines go first.  This measures what the user feels: the round trip of a console line
(``?97.1`` and the fence ``?96.1`` the host library sends after it, both answered with
their echoes) through :class:`coolmuscle.tools.web.line.LineDevice`, on the stand-in
for a motor at 38.4 kbps (``coolmuscle sim --pty --pace``, a process of its own), in
two set-ups side by side, alternating, in one run:

* ``unpolled``  the line with nothing else on it;
* ``polled``    the page's poll running (9 rounds a second at 38.4 kbps, a quarter of
                the line at most).

The lines go out at random moments (0..60 ms apart), so they meet the poll in every
phase.  Printed: p50 / p99 / max of each, the ratios polled / unpolled, the poll's
rounds a second and the share of the line the motor's answers took (bytes from the
motor x 10 bits / 38400 / seconds, console included).  Goal: p99 polled at most the
unpolled p99 plus one poll query on the line (about 6 ms).  About 2 x ``--rounds`` x
``--lines`` x 0.05 s::

    PYTHONPATH=src python bench/bench_desk.py [--lines 200] [--rounds 3]
"""

from __future__ import annotations

import argparse
import asyncio
import random
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

from coolmuscle.testing.served import ServedSim
from coolmuscle.tools.web.line import LineDevice, open_line

BAUD = 38400


def _realtime() -> list[str]:
    """``chrt -f 20`` where allowed: a real motor has a processor of its own."""
    if shutil.which("chrt") is None:
        return []
    allowed = subprocess.run(["chrt", "-f", "20", "true"], capture_output=True)
    return ["chrt", "-f", "20"] if allowed.returncode == 0 else []


async def _run(pty: str, polled: bool, lines: int, seed: int) -> tuple[list[float], float,
                                                                         float]:
    """Console round trips (s), poll rounds a second, share of the line from the motor."""
    opened, found = await asyncio.to_thread(open_line, pty)
    line = LineDevice(opened, found, poll=polled)
    received = [0]
    line.taps.append(lambda direction, data: received.__setitem__(
        0, received[0] + (len(data) if direction == "<" else 0)))
    line.start()
    rng = random.Random(seed)
    try:
        await asyncio.sleep(1.0)                 # the poll's first rounds
        rounds0, start, received[0] = line.rounds, time.perf_counter(), 0
        times: list[float] = []
        for _ in range(lines):
            await asyncio.sleep(rng.uniform(0.0, 0.06))
            t0 = time.perf_counter()
            replies = await line.console("?97.1", 1)
            times.append(time.perf_counter() - t0)
            assert replies and replies[0].startswith("Sx.1="), replies
        seconds = time.perf_counter() - start
        return (times, (line.rounds - rounds0) / seconds,
                received[0] * 10 / BAUD / seconds)
    finally:
        await line.close()


def _pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--lines", type=int, default=200, help="console lines a set-up a round")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-desk-") as tmp:
        sim = ServedSim(Path(tmp) / "sim.log", "--pace", tcp=False, pty=True,
                        prefix=_realtime())
        try:
            results: dict[str, list[float]] = {"unpolled": [], "polled": []}
            rates: list[float] = []
            shares: dict[str, list[float]] = {"unpolled": [], "polled": []}
            for r in range(args.rounds):
                for name in ("unpolled", "polled"):
                    times, rate, share = asyncio.run(_run(sim.pty, name == "polled",
                                                          args.lines, seed=r))
                    results[name] += times
                    shares[name].append(share)
                    if name == "polled":
                        rates.append(rate)
        finally:
            sim.close()
    print(f"console round trip of '?97.1' (+ its ?96.1 fence) at {BAUD} bit/s on the paced "
          f"pty stand-in, {args.rounds} x {args.lines} lines a set-up")
    print(f"{'set-up':<10} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8} {'line used':>10}")
    for name, values in results.items():
        share = sum(shares[name]) / len(shares[name])
        print(f"{name:<10} {_pct(values, 0.5) * 1e3:8.1f} {_pct(values, 0.99) * 1e3:8.1f} "
              f"{max(values) * 1e3:8.1f} {share:10.0%}")
    base, polled = results["unpolled"], results["polled"]
    print(f"ratio polled / unpolled: p50 {_pct(polled, 0.5) / _pct(base, 0.5):.2f}x, "
          f"p99 {_pct(polled, 0.99) / _pct(base, 0.99):.2f}x; "
          f"p99 difference {(_pct(polled, 0.99) - _pct(base, 0.99)) * 1e3:+.1f} ms; "
          f"poll {sum(rates) / len(rates):.1f} rounds a second")


if __name__ == "__main__":
    main()
