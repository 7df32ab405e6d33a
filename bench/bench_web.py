"""Benchmark: the host line's round trip with 20 dashboard pages watching a 15-motor chain.

The same ``?96.1`` round trip as bench_roundtrip.py (TCP on loopback, echo and reply),
measured side by side on a 15-motor chain whose motors all move (so the dashboard
sends snapshots all the time), in three set-ups:

* ``tcp only``          the chain behind TCP, no dashboard;
* ``web, no page``      the dashboard transport running, nobody watching;
* ``web, 20 pages``     20 WebSocket clients (in another process, as browsers are)
                        receiving every frame.

Printed: p50 / p99 round trip of each, the ratios to ``tcp only`` (goal: at most
1.2x with 20 pages) and the snapshot rate each page received (goal: >= 20 a second).
Runs in about 3 x ``--rounds`` x (``--seconds`` + 2) seconds::

    PYTHONPATH=src python bench/bench_web.py [--seconds 5] [--pages 20] [--rounds 2]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing
import socket
import statistics
import time
from typing import Any

from coolmuscle.chain import Chain
from coolmuscle.frontends.transports import create
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.tools.web.server import WebTransport

MOTORS = 15
QUERY = b"?96.1\r"


def _moves() -> bytes:
    """Every motor on a long slow move (2.1.1 S, A, P, ^), back and forth."""
    lines = [", ".join(f"S.{m}=5, A.{m}=50, P.{m}={1_000_000 * (1 if m % 2 else -1)}"
                       for m in range(1, MOTORS + 1)),
             ", ".join(f"^.{m}" for m in range(1, MOTORS + 1))]
    return "\r".join(lines).encode() + b"\r"


def _read_until(sock: socket.socket, buf: bytearray, marker: bytes) -> None:
    while True:
        at = buf.find(marker)
        if at >= 0:
            end = buf.find(b"\r", at)
            if end >= 0:
                del buf[:end + 1]
                return
        chunk = sock.recv(65536)
        if not chunk:
            raise ConnectionError("host line closed")
        buf += chunk


def round_trips(port: int, seconds: float) -> list[float]:
    """``?96.1`` round trips (s) for ``seconds`` on the TCP host line."""
    times: list[float] = []
    with socket.create_connection(("127.0.0.1", port), 5) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        buf = bytearray()
        sock.sendall(_moves())
        time.sleep(0.5)
        sock.setblocking(False)
        try:
            while sock.recv(65536):
                pass
        except BlockingIOError:
            pass
        sock.setblocking(True)
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            t0 = time.perf_counter()
            sock.sendall(QUERY)
            _read_until(sock, buf, b"Px.1=")
            times.append(time.perf_counter() - t0)
    return times


def _pages(url: str, pages: int, seconds: float, out: Any) -> None:
    """Child process: ``pages`` WebSocket clients; puts each one's snapshot count."""
    import aiohttp

    async def page(session: Any) -> int:
        async with session.ws_connect(url + "ws", max_msg_size=0) as ws:
            count, end = 0, time.monotonic() + seconds
            while time.monotonic() < end:
                msg = await ws.receive(timeout=5)
                count += sum(json.loads(line).get("t") == "snap"
                             for line in msg.data.split("\n"))
            return count

    async def main() -> list[int]:
        async with aiohttp.ClientSession() as session:
            return list(await asyncio.gather(*(page(session) for _ in range(pages))))
    out.put(asyncio.run(main()))


def run(web: bool, pages: int, seconds: float) -> tuple[list[float], list[int]]:
    transports = (lambda: [create("tcp", port=0), WebTransport(port=0)]) if web \
        else (lambda: [create("tcp", port=0)])
    with ServiceThread(lambda: Chain(motors=MOTORS), transports) as st:
        port = st.transports[0].info()["port"]
        child, queue = None, None
        if pages:
            queue = multiprocessing.get_context("spawn").Queue()
            child = multiprocessing.get_context("spawn").Process(
                target=_pages, args=(st.transports[1].url, pages, seconds + 1.5, queue))
            child.start()
            time.sleep(1.0)                     # the pages connect
        times = round_trips(port, seconds)
        counts: list[int] = []
        if child is not None and queue is not None:
            counts = queue.get(timeout=seconds + 30)
            child.join(10)
    return times, counts


def _p(times: list[float], q: float) -> float:
    return sorted(times)[min(len(times) - 1, int(q * len(times)))] * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--pages", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=2,
                        help="Alternate the set-ups this many times (a shared machine is noisy).")
    args = parser.parse_args()
    setups = (("tcp only", False, 0), ("web, no page", True, 0),
              (f"web, {args.pages} pages", True, args.pages))
    pooled: dict[str, tuple[list[float], list[int]]] = {name: ([], []) for name, _, _ in setups}
    for _ in range(args.rounds):
        for name, web, pages in setups:
            times, counts = run(web, pages, args.seconds)
            pooled[name][0].extend(times)
            pooled[name][1].extend(counts)
    rows = [(name, *pooled[name]) for name, _, _ in setups]
    base = statistics.median(rows[0][1])
    print(f"?96.1 round trip over TCP, {MOTORS}-motor chain, every motor moving "
          f"({args.rounds} x {args.seconds:g} s each, set-ups alternated)")
    print(f"{'set-up':<16} {'queries':>8} {'mean ms':>8} {'p50 ms':>8} {'p99 ms':>8} "
          f"{'p50 ratio':>10} {'mean ratio':>11}  snapshots/s per page (min / mean)")
    base_mean = statistics.mean(rows[0][1])
    for name, times, counts in rows:
        rate = (f"{min(counts) / (args.seconds + 1.5):.1f} / "
                f"{statistics.mean(counts) / (args.seconds + 1.5):.1f}") if counts else "-"
        print(f"{name:<16} {len(times):>8} {statistics.mean(times) * 1e3:>8.3f} "
              f"{_p(times, .5):>8.3f} {_p(times, .99):>8.3f} "
              f"{statistics.median(times) / base:>9.2f}x "
              f"{statistics.mean(times) / base_mean:>10.2f}x  {rate}")
    print("goal: p50 ratio <= 1.2x with the pages connected, >= 20 snapshots/s per page")
    print("(queries: round trips done back to back in the time; the machine's other load "
          "shows in the mean and p99)")


if __name__ == "__main__":
    main()
