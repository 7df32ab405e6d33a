"""Benchmark: the ``?96.1`` round trip over TCP against the RS-232 wire time of the same bytes.

A client on loopback sends ``?96.1\\r`` and waits for the echo and the ``Px.1=...``
reply, again and again.  Printed: p50 / p99 round trip, queries per second, and the
wire time of the same bytes (query + echo + reply, 10 bits a byte) at 38.4 and
230.4 kbps with the ratios.  A second, short run with wire pacing on (``--pace``)
shows the paced round trip next to the 38.4 kbps wire time (ratio ~1 expected).

Uses the real ``Chain`` when it answers ``?96.1``; until the motor model lands it
falls back to ``tests/fakes.FakeChain`` (same HostLine) and says so.  Runs < 30 s::

    PYTHONPATH=src python bench/bench_roundtrip.py [--seconds 8]
"""

from __future__ import annotations

import argparse
import socket
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport

QUERY = b"?96.1\r"
BAUDS = (38400, 230400)


def _fake_factory(pacing: bool) -> Callable[[], Any]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from fakes import FakeChain
    return lambda: FakeChain(pacing=pacing)


def _answers(make: Callable[[], Any]) -> bool:
    with ServiceThread(make, lambda: [TcpTransport(port=0)]) as st:
        with socket.create_connection(("127.0.0.1", st.transports[0].info()["port"]), 2) as sock:
            sock.sendall(QUERY)
            got = b""
            deadline = time.monotonic() + 0.5
            try:
                while b"Px.1=" not in got and time.monotonic() < deadline:
                    sock.settimeout(max(0.01, deadline - time.monotonic()))
                    got += sock.recv(4096)
            except (TimeoutError, OSError):
                pass
            return b"Px.1=" in got


def _round_trips(make: Callable[[], Any], seconds: float, limit: int) -> tuple[list[float], int]:
    """Return (round-trip times in s, bytes echoed+replied per query)."""
    times: list[float] = []
    reply_bytes = 0
    with ServiceThread(make, lambda: [TcpTransport(port=0)]) as st:
        port = st.transports[0].info()["port"]
        with socket.create_connection(("127.0.0.1", port), 5) as sock:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.settimeout(5)
            end = time.monotonic() + seconds
            warmup = 100
            while len(times) < limit and time.monotonic() < end:
                start = time.perf_counter()
                sock.sendall(QUERY)
                got = b""
                while not (b"Px.1=" in got and got.endswith(b"\n")):
                    chunk = sock.recv(4096)
                    if not chunk:
                        raise ConnectionError("server closed the connection")
                    got += chunk
                elapsed = time.perf_counter() - start
                reply_bytes = len(got)
                if warmup:
                    warmup -= 1
                    continue
                times.append(elapsed)
    return times, reply_bytes


def _pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=8.0, help="unpaced run length")
    parser.add_argument("--queries", type=int, default=50_000, help="unpaced query limit")
    args = parser.parse_args()

    make: Callable[[], Any] = lambda: Chain()  # noqa: E731
    paced: Callable[[], Any] = lambda: Chain(pacing=True)  # noqa: E731
    label = "coolmuscle.chain.daisy.Chain"
    if not _answers(make):
        make, paced = _fake_factory(False), _fake_factory(True)
        label = "tests/fakes.FakeChain (the Chain placeholder does not answer ?96.1 yet)"

    times, back = _round_trips(make, args.seconds, args.queries)
    wire_bytes = len(QUERY) + back
    p50, p99 = _pct(times, 0.50), _pct(times, 0.99)
    qps = len(times) / sum(times)
    print(f"?96.1 round trip over TCP loopback, chain: {label}")
    print(f"  unpaced: {len(times)} queries   p50 {p50 * 1e6:8.1f} us   p99 {p99 * 1e6:8.1f} us"
          f"   {qps:9.0f} queries/s")
    print(f"  wire time of the same {wire_bytes} bytes (query {len(QUERY)} + echo and reply "
          f"{back}), 10 bits a byte:")
    for baud in BAUDS:
        wire = wire_bytes * 10 / baud
        print(f"    {baud / 1000:6.1f} kbps: {wire * 1e3:7.3f} ms   wire/p50 = {wire / p50:7.1f}x"
              f"   wire/p99 = {wire / p99:7.1f}x")

    ptimes, _ = _round_trips(paced, 3.0, 300)
    pp50, pp99 = _pct(ptimes, 0.50), _pct(ptimes, 0.99)
    wire = wire_bytes * 10 / 38400
    print(f"  paced (--pace, K20 = 38.4 kbps): {len(ptimes)} queries   p50 {pp50 * 1e3:7.3f} ms"
          f"   p99 {pp99 * 1e3:7.3f} ms   p50/wire = {pp50 / wire:5.2f}")


if __name__ == "__main__":
    main()
