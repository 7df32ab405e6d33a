"""Benchmark: commands per second through the host library, next to the raw socket.

The same round trip, ``?96.1`` answered by ``Px.1=...`` (6.6), each target next to
its raw baseline:

* TCP loopback: a raw socket (as bench/bench_roundtrip.py: send, read to the reply),
  then ``coolmuscle.connect("socket://...")`` (``m.position``) and the asyncio client
  (``await m.get_position()``) on the same server;
* in-process: raw pyserial on ``coolmuscle://?mode=fast`` (write, ``read_until``),
  then the client on the same kind of port.

It also times a write that is read back (``m.write_register("P", 1, n)``: the
assignment, its readback query and a fence in one exchange).  Printed: operations per
second, p50 / p99, and the client overhead as a ratio (raw rate / client rate).
Runs in about 20 s::

    PYTHONPATH=src python bench/bench_client.py [--seconds 3]
"""

from __future__ import annotations

import argparse
import asyncio
import socket
import time
from collections.abc import Callable
from typing import Any

from coolmuscle import connect, connect_async
from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport

QUERY = b"?96.1\r"


def _measure(step: Callable[[], Any], seconds: float, warmup: int = 50) -> list[float]:
    for _ in range(warmup):
        step()
    times: list[float] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        start = time.perf_counter()
        step()
        times.append(time.perf_counter() - start)
    return times


def _raw_socket(port: int, seconds: float) -> list[float]:
    with socket.create_connection(("127.0.0.1", port), 5) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(5)

        def step() -> None:
            sock.sendall(QUERY)
            got = b""
            while not (b"Px.1=" in got and got.endswith(b"\n")):
                chunk = sock.recv(4096)
                if not chunk:
                    raise ConnectionError("server closed the connection")
                got += chunk
        return _measure(step, seconds)


def _raw_inprocess(seconds: float) -> list[float]:
    import serial

    from coolmuscle import register_url_handler
    register_url_handler()
    with serial.serial_for_url("coolmuscle://?mode=fast", timeout=1) as port:
        def step() -> None:
            port.write(QUERY)
            got = port.read_until(b"\n")          # the echo
            got = port.read_until(b"\n")          # Px.1=...
            if not got.startswith(b"Px.1="):
                raise RuntimeError(f"unexpected {got!r}")
        return _measure(step, seconds)


def _sync(url: str, seconds: float, what: str) -> list[float]:
    with connect(url) as m:
        if what == "query":
            return _measure(lambda: m.position, seconds)
        counter = iter(range(10 ** 9))
        return _measure(lambda: m.write_register("P", 1, next(counter)), seconds)


def _async(url: str, seconds: float) -> list[float]:
    async def main() -> list[float]:
        async with await connect_async(url) as m:
            for _ in range(50):
                await m.get_position()
            times: list[float] = []
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                start = time.perf_counter()
                await m.get_position()
                times.append(time.perf_counter() - start)
            return times
    return asyncio.run(main())


def _pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def _row(label: str, times: list[float], raw_rate: float | None) -> None:
    rate = len(times) / sum(times)
    ratio = f"{raw_rate / rate:6.2f}x" if raw_rate else "   1.00x"
    print(f"  {label:<44} {rate:9.0f} /s   p50 {_pct(times, .5) * 1e6:8.1f} us"
          f"   p99 {_pct(times, .99) * 1e6:8.1f} us   overhead {ratio}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="length of each run")
    args = parser.parse_args()
    with ServiceThread(lambda: Chain(), lambda: [TcpTransport(port=0)]) as service:
        port = service.transports[0].info()["port"]
        url = f"socket://127.0.0.1:{port}"
        raw = _raw_socket(port, args.seconds)
        raw_rate = len(raw) / sum(raw)
        print("?96.1 round trips over TCP loopback (overhead = raw rate / client rate)")
        _row("raw socket", raw, None)
        _row("client m.position, socket://", _sync(url, args.seconds, "query"), raw_rate)
        _row("asyncio client get_position(), socket://", _async(url, args.seconds), raw_rate)
        _row("client write_register (P1.1=n, P1.1, ?96.1)", _sync(url, args.seconds, "write"),
             raw_rate)
    inproc = _raw_inprocess(args.seconds)
    inproc_rate = len(inproc) / sum(inproc)
    fast = "coolmuscle://?mode=fast"
    print("?96.1 round trips in-process, coolmuscle://?mode=fast")
    _row("raw pyserial write + read_until", inproc, None)
    _row("client m.position", _sync(fast, args.seconds, "query"), inproc_rate)
    _row("client write_register (P1.1=n, P1.1, ?96.1)", _sync(fast, args.seconds, "write"),
         inproc_rate)


if __name__ == "__main__":
    main()
