"""Benchmark: our Modbus slave next to pymodbus' server, and RTU round trips next to the wire.

1. **Modbus TCP, side by side.** Two servers, each in its own process: ``coolmuscle sim
   --modbus-tcp`` and pymodbus' own server (``ModbusTcpServer`` with its simulator
   data model, ``SimDevice``) holding the same ten registers.  The same pymodbus
   client code reads those registers (FC03, K78+200..209 = P0..P4) one request after
   the other, alternating slices of 100 requests between the two servers.  Printed:
   requests/s, p50 and p99 latency, and our/pymodbus ratios (goal: at least as fast).
2. **Modbus RTU over a pty at 115.2 kbps** (K20=4, written by Modbus first): a bare
   pyserial port sends one FC03 frame and reads the exact 9-byte answer (so no client
   library's polling is measured); the round trip is printed next to the wire time of
   the same bytes (8 + 9 bytes, 10 bits a byte) and next to wire time plus the 5.6.2
   silent interval (0.56 ms) a real slave waits before answering.  A second run with
   ``--pace`` makes the virtual wire take that time itself.

Runs in about 20 s::

    PYTHONPATH=src python bench/bench_modbus.py [--seconds 5]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pymodbus.client import ModbusSerialClient, ModbusTcpClient

ROOT = Path(__file__).resolve().parents[1]
REGISTERS = (200, 10)                       # P0..P4 with K78=0
P0 = 12345
BAUD = 115200

PYMODBUS_SERVER = r"""
import asyncio, sys
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice
values = [0, %d] + [0] * 8
device = SimDevice(id=1, simdata=[SimData(address=200, values=values,
                                          datatype=DataType.REGISTERS)])
async def serve():
    server = ModbusTcpServer(device, address=("127.0.0.1", int(sys.argv[1])))
    print("ready", flush=True)
    await server.serve_forever()
asyncio.run(serve())
""" % P0


def _wait_port(port: int, timeout: float = 10.0) -> None:
    """Wait until something accepts TCP connections on ``port`` (servers print "ready"
    before they bind)."""
    import socket
    deadline = time.monotonic() + timeout
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
            return
        except OSError:
            if time.monotonic() > deadline:
                raise RuntimeError(f"nothing listens on 127.0.0.1:{port}") from None
            time.sleep(0.05)


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start(args: list[str], ready: Callable[[str], bool]) -> tuple[subprocess.Popen[str], str]:
    path = f"{ROOT / 'src'}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"
    proc = subprocess.Popen([sys.executable, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONPATH": path})
    assert proc.stdout is not None
    seen = ""
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        seen += line
        if ready(seen):
            return proc, seen
    proc.kill()
    raise RuntimeError(f"server did not start: {seen}")


def _stop(proc: subprocess.Popen[str]) -> None:
    proc.terminate()
    try:
        proc.wait(5)
    except subprocess.TimeoutExpired:
        proc.kill()


def _measure(read: Callable[[], Any], seconds: float, warmup: int = 200,
             count: int | None = None) -> list[float]:
    for _ in range(warmup):
        read()
    times: list[float] = []
    end = time.monotonic() + seconds
    while (len(times) < count) if count is not None else (time.monotonic() < end):
        start = time.perf_counter()
        read()
        times.append(time.perf_counter() - start)
    return times


def _pct(times: list[float], q: float) -> float:
    ordered = sorted(times)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def _row(name: str, times: list[float]) -> str:
    return (f"  {name:<18} {len(times) / sum(times):8.0f} req/s   "
            f"p50 {_pct(times, .5) * 1e6:6.0f} us   p99 {_pct(times, .99) * 1e6:6.0f} us")


def tcp_side_by_side(seconds: float) -> None:
    ours, banner = _start(["-m", "coolmuscle", "sim", "--no-state", "--modbus-tcp", "0"],
                          lambda s: "modbus-tcp:" in s)
    found = re.search(r"modbus-tcp: 127\.0\.0\.1:(\d+)", banner)
    assert found is not None, banner
    their_port = _free_port()
    theirs, _ = _start(["-c", PYMODBUS_SERVER, str(their_port)], lambda s: "ready" in s)
    _wait_port(their_port)
    results: dict[str, list[float]] = {"coolmuscle": [], "pymodbus server": []}
    clients: dict[str, Any] = {}
    try:
        for name, port in (("coolmuscle", int(found.group(1))), ("pymodbus server", their_port)):
            client = clients[name] = ModbusTcpClient("127.0.0.1", port=port, timeout=2,
                                                     retries=0)
            assert client.connect(), name
            if name == "coolmuscle":
                client.write_registers(200, [0, P0], device_id=1)
            first = client.read_holding_registers(REGISTERS[0], count=REGISTERS[1], device_id=1)
            assert not first.isError() and first.registers[:2] == [0, P0], (name, first)
        # Alternate slices of 100 requests, so a busy machine slows both alike.
        slices = max(1, int(seconds * 2 * 40))
        for i in range(slices):
            for name, client in clients.items():
                def read(c: Any = client) -> None:
                    reply = c.read_holding_registers(REGISTERS[0], count=REGISTERS[1],
                                                     device_id=1)
                    assert not reply.isError()
                results[name] += _measure(read, 0, warmup=200 if i == 0 else 0, count=100)
    finally:
        for client in clients.values():
            client.close()
        _stop(ours)
        _stop(theirs)
    print(f"Modbus TCP, FC03 x{REGISTERS[1]} registers, the same pymodbus client code, "
          f"{len(results['coolmuscle'])} requests each, in alternating slices of 100:")
    for name, times in results.items():
        print(_row(name, times))
    ours_t, theirs_t = results["coolmuscle"], results["pymodbus server"]
    rate = (len(ours_t) / sum(ours_t)) / (len(theirs_t) / sum(theirs_t))
    p99 = _pct(theirs_t, .99) / _pct(ours_t, .99)
    verdict = "goal met" if rate >= 1 and p99 >= 1 else "goal NOT met"
    print(f"  ours vs pymodbus: throughput x{rate:.2f}, p99 x{p99:.2f} faster ({verdict})")


def _rtu(body: bytes) -> bytes:
    from coolmuscle.chain.firmware_modbus.rtu import crc16
    return body + crc16(body)


def rtu_round_trip(seconds: float, pace: bool) -> list[float]:
    """Round trips of one FC03 frame over the pty, timed with a bare pyserial port."""
    import serial

    args = ["-m", "coolmuscle", "sim", "--no-state", "--modbus-rtu", "pty"]
    proc, banner = _start(args + (["--pace"] if pace else []), lambda s: "modbus-rtu:" in s)
    found = re.search(r"modbus-rtu: (\S+)", banner)
    assert found is not None, banner
    path = found.group(1)
    try:
        client = ModbusSerialClient(path, baudrate=38400, timeout=2, retries=0)
        assert client.connect()
        assert not client.write_registers(752, [0, 4], device_id=1).isError()   # K20=4
        assert not client.write_registers(200, [0, P0], device_id=1).isError()
        client.close()
        request = _rtu(bytes.fromhex("01 03 00 C8 00 02"))
        expected = _rtu(bytes.fromhex("01 03 04 00 00") + P0.to_bytes(2, "big"))
        with serial.Serial(path, BAUD, timeout=2) as port:
            port.reset_input_buffer()

            def read() -> None:
                port.write(request)
                got = port.read(len(expected))
                assert got == expected, got.hex()
            return _measure(read, seconds, warmup=50)
    finally:
        _stop(proc)


def main() -> None:
    parser = argparse.ArgumentParser(description="Modbus TCP and RTU benchmark")
    parser.add_argument("--seconds", type=float, default=5.0)
    opts = parser.parse_args()
    tcp_side_by_side(opts.seconds)
    wire = (8 + 9) * 10 / BAUD
    gap = 64 / BAUD
    print(f"\nModbus RTU over a pty at 115.2 kbps, FC03 x2 registers (8 + 9 bytes): wire time "
          f"{wire * 1e3:.2f} ms, wire + 5.6.2 interval {(wire + gap) * 1e3:.2f} ms")
    for pace in (False, True):
        times = rtu_round_trip(opts.seconds / 2, pace)
        p50 = statistics.median(times)
        print(_row("paced (--pace)" if pace else "unpaced", times)
              + f"   p50/wire x{p50 / wire:.2f}, p50/(wire+interval) x{p50 / (wire + gap):.2f}")


if __name__ == "__main__":
    main()
