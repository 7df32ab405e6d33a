"""Benchmark: the long versions of the reliability suite (docs/reliability.md).

Printed, side by side:

* **clients**: 20 clients x 1,000 queries (``V<n>.1=i`` then ``?96.m``) on the real
  chain over TCP: lost / duplicated / reordered counts (0 expected) and the time;
* **fairness**: the p50 / p99 round trip of a one-at-a-time ``?96.2`` client alone,
  then while another client floods (``?99.1`` without pause), and the ratio;
* **kill -9**: ROUNDS kills of ``coolmuscle sim`` during ``$`` (cml-users-guide.txt
  2.1.2): store damaged / state other than the last acknowledged save or the one in
  flight (0 expected);
* **trace**: ``coolmuscle run --trace --trace-step 0.01`` of a program bank looping
  moves (``X0``, 2.2.2) for HOURS virtual hours: peak RSS, wall time, file size;
  and the same run without ``--trace`` (the ratio is the trace's cost).

::

    PYTHONPATH=src python bench/bench_reliability.py [--rounds 100] [--hours 10]
        [--only clients,fairness,kill,trace]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import random
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from load_support import Flood, connect, round_trip, save_then_kill, saved_value, start_sim  # noqa: E402

SRC = str(Path(__file__).resolve().parents[1] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC}


# -- 20 clients x 1,000 queries -----------------------------------------------------------
def clients(n_clients: int = 20, queries: int = 1000) -> None:
    with ServiceThread(lambda: Chain(motors=15), lambda: [TcpTransport(port=0)]) as st_:
        port = st_.transports[0].info()["port"]
        total = n_clients * queries * 3

        async def client(n: int, go: asyncio.Event) -> list[bytes]:
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            await go.wait()
            writer.write(b"".join(b"V%d.1=%d\r?96.%d\r" % (n + 1, i, n % 15 + 1)
                                  for i in range(queries)))
            await writer.drain()
            data = bytearray()
            while data.count(b"\r\n") < total:
                chunk = await asyncio.wait_for(reader.read(1 << 16), 120)
                if not chunk:
                    break
                data += chunk
            writer.close()
            return bytes(data).split(b"\r\n")[:-1]

        async def main() -> list[list[bytes]]:
            go = asyncio.Event()
            tasks = asyncio.gather(*(client(n, go) for n in range(n_clients)))
            while st_.transports[0].clients < n_clients:
                await asyncio.sleep(0.01)
            go.set()
            return await tasks

        start = time.perf_counter()
        results = asyncio.run(main())
        elapsed = time.perf_counter() - start
        dropped = st_.transports[0].dropped_clients
    lost = dup = reordered = 0
    stream = results[0]
    for n in range(n_clients):
        values = [int(line.split(b"=")[1]) for line in stream
                  if line.startswith(b"V%d.1=" % (n + 1))]
        lost += len(set(range(queries)) - set(values))
        dup += len(values) - len(set(values))
        reordered += sum(1 for a, b in zip(values, values[1:]) if b < a)
    unpaired = sum(1 for i, line in enumerate(stream) if line.startswith(b"?96.")
                   and not (i + 1 < len(stream) and stream[i + 1].startswith(b"Px.")))
    differ = sum(1 for other in results[1:] if other != stream)
    print(f"clients   {n_clients} x {queries}: {elapsed:.2f} s, "
          f"{n_clients * queries * 2 / elapsed:,.0f} lines/s; lost {lost}, duplicated {dup}, "
          f"reordered {reordered}, query without its reply {unpaired}, clients that saw "
          f"another stream {differ}, dropped {dropped}")


# -- fairness: p99 of one-at-a-time while another floods -------------------------------------
def _trips(port: int, count: int) -> list[float]:
    with connect(port) as probe:
        return sorted(round_trip(probe, b"?96.2\r", b"Px.2=") for _ in range(count))


def fairness(count: int = 500) -> None:
    with ServiceThread(lambda: Chain(motors=2), lambda: [TcpTransport(port=0)]) as st_:
        port = st_.transports[0].info()["port"]
        alone = _trips(port, count)
        with Flood(connect(port)) as flood:
            time.sleep(0.3)
            loaded = _trips(port, count)
        sent = flood.sent
    a50, a99 = alone[count // 2], alone[int(count * 0.99)]
    l50, l99 = loaded[count // 2], loaded[int(count * 0.99)]
    print(f"fairness  ?96.2 round trip alone p50 {a50 * 1e3:.2f} ms p99 {a99 * 1e3:.2f} ms | "
          f"while another floods ({sent:,} lines) p50 {l50 * 1e3:.2f} ms p99 "
          f"{l99 * 1e3:.2f} ms | ratio p99 {l99 / a99:.1f}x")


# -- kill -9 during $ ------------------------------------------------------------------------
def kill9(rounds: int) -> None:
    rng = random.Random(99)
    damaged = wrong = 0
    with tempfile.TemporaryDirectory() as tmp:
        state = Path(tmp) / "state"
        acknowledged = 0
        start = time.perf_counter()
        for _ in range(rounds):
            try:
                proc, port = start_sim(state, ENV)
            except RuntimeError as exc:
                raise SystemExit(f"sim did not start: {exc}") from None
            acknowledged = save_then_kill(proc, port, acknowledged, rng.uniform(0.05, 0.5),
                                          rng.uniform(0, 0.003))
            whole, saved = saved_value(state)
            damaged += not whole
            if saved not in (acknowledged, acknowledged + 1):
                wrong += 1
            acknowledged = saved
        elapsed = time.perf_counter() - start
    print(f"kill -9   {rounds} rounds during $ ({elapsed:.0f} s): damaged store {damaged}, "
          f"state other than the last save or the one in flight {wrong}")


# -- a long traced run -------------------------------------------------------------------------
SCRIPT = """S1.1=100
A1.1=100
P1.1=20000
P2.1=0
T1.1=200
B1.1
X0.1
S1.1, A1.1, P1.1
T1.1
P2.1
T1.1
X.1-
END
[1.1
@wait {seconds}
?96.1
"""


def _run(script: Path, extra: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MiB) of ``coolmuscle run`` in a child process."""
    code = ("import resource, runpy, sys; sys.argv = ['coolmuscle', 'run'] + sys.argv[1:];\n"
            "try:\n    runpy.run_module('coolmuscle', run_name='__main__')\n"
            "finally:\n    print('RSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,"
            " file=sys.stderr)")
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", code, str(script), *extra],
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=ENV)
    elapsed = time.perf_counter() - start
    found = re.search(r"RSS (\d+)", done.stderr)
    if done.returncode != 0 or not found:
        raise SystemExit(f"run failed: {done.stderr[-500:]}")
    return elapsed, int(found.group(1)) / 1024


def trace(hours: float) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "long.cml"
        script.write_text(SCRIPT.format(seconds=int(hours * 3600)))
        out = Path(tmp) / "long.csv"
        plain_s, plain_mb = _run(script, [])
        traced_s, traced_mb = _run(script, ["--trace", str(out), "--trace-step", "0.01"])
        size = out.stat().st_size / (1 << 20)
        rows = sum(1 for _ in out.open()) - 1
    print(f"trace     {hours:g} h looping moves, --trace-step 0.01: peak RSS {traced_mb:.0f} MiB "
          f"(without --trace {plain_mb:.0f} MiB), wall {traced_s:.0f} s (without "
          f"{plain_s:.1f} s, ratio {traced_s / plain_s:.0f}x), {rows:,} rows, {size:.0f} MiB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=100)
    parser.add_argument("--hours", type=float, default=10.0)
    parser.add_argument("--only", default="clients,fairness,kill,trace")
    args = parser.parse_args()
    chosen = set(args.only.split(","))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    if "clients" in chosen:
        clients()
    if "fairness" in chosen:
        fairness()
    if "kill" in chosen:
        kill9(args.rounds)
    if "trace" in chosen:
        trace(args.hours)


if __name__ == "__main__":
    main()
