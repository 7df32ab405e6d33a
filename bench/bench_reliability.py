"""Benchmark: the long versions of the reliability suite (docs/reliability.md).

Printed, side by side:

* **clients**: 20 clients x 1,000 queries (``V<n>.1=i`` then ``?96.m``) on the real
  chain over TCP: lost / duplicated / reordered counts (0 expected) and the time;
* **fairness**: the p50 / p99 round trip of a one-at-a-time ``?96.2`` client alone,
  then while another client floods (``?99.1`` without pause), and the ratio;
* **web flood**: the p50 / p99 round trip of a one-at-a-time ``?96.1`` host-line
  client over TCP alone, then beside PAGES dashboard pages (WebSocket clients in
  another process, as browsers are) each pipelining ``?96.1`` console requests
  without pause, and the ratio (goal: p99 <= 50 ms beside 20 pages);
* **web heavy**: the same host-line client alone, then beside a page uploading
  banks back to back (a 48 KiB bank text, then a valid 450-line bank: checked in a
  worker thread, sent in slices) and a client downloading the plot of the recording
  back to back while two motors move (drawn in a worker thread);
* **kill -9**: ROUNDS kills of ``coolmuscle sim`` during ``$`` (cml-users-guide.txt
  2.1.2): store damaged / state other than the last acknowledged save or the one in
  flight (0 expected);
* **trace**: ``coolmuscle run --trace --trace-step 0.01`` of a program bank looping
  moves (``X0``, 2.2.2) for HOURS virtual hours: peak RSS, wall time, file size;
  and the same run without ``--trace`` (the ratio is the trace's cost).

::

    PYTHONPATH=src python bench/bench_reliability.py [--rounds 100] [--hours 10]
        [--pages 20] [--only clients,fairness,webflood,webheavy,kill,trace]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing
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
from fixtures import ServedSim  # noqa: E402
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


# -- web flood: the host line's p99 beside pages pipelining console requests --------------
def _flooding_pages(url: str, pages: int, seconds: float, out: object) -> None:
    """Child process: ``pages`` WebSocket clients, each sending ``?96.1`` console requests
    back to back (never waiting for an answer) and reading what comes; puts the count
    of requests sent and of answers received."""
    import aiohttp

    async def page(session: aiohttp.ClientSession) -> tuple[int, int]:
        sent = answered = 0

        async def read(ws: aiohttp.ClientWebSocketResponse) -> None:
            nonlocal answered
            async for msg in ws:
                if msg.type != aiohttp.WSMsgType.TEXT:
                    break
                answered += msg.data.count('"t":"result"')
        try:
            async with session.ws_connect(url + "ws", max_msg_size=0) as ws:
                reader = asyncio.create_task(read(ws))
                end = time.monotonic() + seconds
                while time.monotonic() < end:
                    await ws.send_str(json.dumps({"t": "cml", "id": sent, "line": "?96.1",
                                                  "motor": 1}))
                    sent += 1
                reader.cancel()
        except (aiohttp.ClientError, ConnectionError):
            pass                                # the page leaves however it can
        return sent, answered

    async def main() -> list[tuple[int, int]]:
        async with aiohttp.ClientSession() as session:
            return list(await asyncio.gather(*(page(session) for _ in range(pages))))
    out.put(asyncio.run(main()))  # type: ignore[attr-defined]


def web_flood(pages: int = 20, seconds: float = 5.0) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        sim = ServedSim(Path(tmp) / "sim.log", "--motors", "2", web=True, env=ENV)
        try:
            alone = _timed_trips(sim.port, seconds)
            context = multiprocessing.get_context("spawn")
            queue = context.Queue()
            child = context.Process(target=_flooding_pages,
                                    args=(sim.web_url, pages, seconds + 3.0, queue))
            child.start()
            time.sleep(2.0)                    # the pages connect and start flooding
            loaded = _timed_trips(sim.port, seconds)
            counts = queue.get(timeout=seconds + 60)
            child.join(10)
            peak = _peak_rss(sim.pid)
        finally:
            sim.close()
    sent, answered = sum(c[0] for c in counts), sum(c[1] for c in counts)
    a50, a99 = _p(alone, .5), _p(alone, .99)
    l50, l99 = _p(loaded, .5), _p(loaded, .99)
    print(f"web flood ?96.1 host line alone p50 {a50:.2f} ms p99 {a99:.2f} ms "
          f"({len(alone)} trips) | beside {pages} pages pipelining ?96.1 ({sent:,} requests "
          f"sent, {answered:,} answered) p50 {l50:.2f} ms p99 {l99:.2f} ms ({len(loaded)} "
          f"trips) | ratio p99 {l99 / a99:.1f}x | sim peak RSS {peak:.0f} MiB | goal p99 "
          f"<= 50 ms: {'met' if l99 <= 50 else 'NOT met'}")


def _peak_rss(pid: int) -> float:
    """Peak resident memory of process ``pid`` in MiB (Linux ``VmHWM``)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _heavy_pages(url: str, seconds: float, out: object) -> None:
    """Child process: one page uploading banks back to back (each waits for its answer),
    one client downloading the plot back to back; puts (uploads, plots) done."""
    import aiohttp

    big = "\n".join(f"B{b}.1\n" + "\n".join(f"S{n % 8 + 1}.1=100, A{n % 8 + 1}.1=100, "
                                               f"P{n % 8 + 1}.1=1000" for n in range(300))
                    + "\nEND" for b in range(1, 4))[:48000]
    valid = "\n".join(["B2.1", *(f"T{n % 8 + 1}.1" for n in range(450)), "END"])

    async def uploads(session: aiohttp.ClientSession, end: float) -> int:
        done = 0
        async with session.ws_connect(url + "ws", max_msg_size=0) as ws:
            while time.monotonic() < end:
                await ws.send_str(json.dumps({"t": "bank_upload", "id": done, "motor": 1,
                                              "text": (big, valid)[done % 2]}))
                async for msg in ws:
                    if f'"t":"result","id":{done},' in msg.data:
                        break
                done += 1
        return done

    async def plots(session: aiohttp.ClientSession, end: float) -> int:
        done = 0
        while time.monotonic() < end:
            async with session.get(url + "api/plot.png") as r:
                await r.read()
                done += r.status == 200
        return done

    async def main() -> tuple[int, int]:
        end = time.monotonic() + seconds
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(url + "ws") as ws:     # record, two motors move
                await ws.send_str(json.dumps({"t": "record", "id": 1}))
                for line in ("S.1=50, A.1=50, P.1=2000000, ^.1",
                             "S.2=50, A.2=50, P.2=-2000000, ^.2"):
                    await ws.send_str(json.dumps({"t": "cml", "id": 2, "line": line}))
                await asyncio.sleep(2.0)
            done = await asyncio.gather(uploads(session, end), plots(session, end))
            return done[0], done[1]
    out.put(asyncio.run(main()))  # type: ignore[attr-defined]


def web_heavy(seconds: float = 5.0) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        sim = ServedSim(Path(tmp) / "sim.log", "--motors", "2", web=True, env=ENV)
        try:
            alone = _timed_trips(sim.port, seconds)
            context = multiprocessing.get_context("spawn")
            queue = context.Queue()
            child = context.Process(target=_heavy_pages,
                                    args=(sim.web_url, seconds + 5.0, queue))
            child.start()
            time.sleep(4.0)                    # recording for 2 s, the heavy work begun
            loaded = _timed_trips(sim.port, seconds)
            uploads, plots = queue.get(timeout=seconds + 120)
            child.join(10)
        finally:
            sim.close()
    a50, a99 = _p(alone, .5), _p(alone, .99)
    l50, l99 = _p(loaded, .5), _p(loaded, .99)
    print(f"web heavy ?96.1 host line alone p50 {a50:.2f} ms p99 {a99:.2f} ms | beside bank "
          f"uploads (48 KiB text / 450-line bank, {uploads} done) and plot downloads "
          f"({plots} done) p50 {l50:.2f} ms p99 {l99:.2f} ms ({len(loaded)} trips) | "
          f"ratio p99 {l99 / a99:.1f}x")


def _timed_trips(port: int, seconds: float) -> list[float]:
    """One-at-a-time ``?96.1`` round trips for ``seconds`` (s each)."""
    trips: list[float] = []
    with connect(port) as probe:
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            trips.append(round_trip(probe, b"?96.1\r", b"Px.1=", timeout=60))
    return trips


def _p(times: list[float], q: float) -> float:
    """The ``q`` quantile of ``times`` in ms."""
    ordered = sorted(times)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] * 1e3


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
    parser.add_argument("--pages", type=int, default=20)
    parser.add_argument("--only", default="clients,fairness,webflood,webheavy,kill,trace")
    args = parser.parse_args()
    chosen = set(args.only.split(","))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    if "clients" in chosen:
        clients()
    if "fairness" in chosen:
        fairness()
    if "webflood" in chosen:
        web_flood(args.pages)
    if "webheavy" in chosen:
        web_heavy()
    if "kill" in chosen:
        kill9(args.rounds)
    if "trace" in chosen:
        trace(args.hours)


if __name__ == "__main__":
    main()
