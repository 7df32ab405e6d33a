"""Helpers for the Modbus tests: an independent CRC, manual frames, a chain on a virtual wire.

The CRC here is the bit-by-bit algorithm of the Modbus specification (polynomial
0xA001, start 0xFFFF), written independently of the pymodbus table the model uses,
and anchored on the well-known frame ``01 03 00 00 00 01 84 0A``.
"""

from __future__ import annotations

import contextlib
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.device.api import Event
from coolmuscle.sim.kernel import NS_PER_S, ms
from fixtures import wait_until

needs_socat = pytest.mark.skipif(shutil.which("socat") is None, reason="socat is not installed")
needs_mbpoll = pytest.mark.skipif(shutil.which("mbpoll") is None, reason="mbpoll is not installed")


def crc(data: bytes) -> bytes:
    """Modbus CRC-16, low byte first, bit by bit."""
    value = 0xFFFF
    for byte in data:
        value ^= byte
        for _ in range(8):
            value = (value >> 1) ^ 0xA001 if value & 1 else value >> 1
    return bytes((value & 0xFF, value >> 8))


def frame(hex_text: str) -> bytes:
    """A frame written as in the manual's tables (hex bytes) with its CRC appended."""
    body = bytes.fromhex(hex_text)
    return body + crc(body)


def gap_ns(baud: int) -> int:
    """5.6.2: 8 byte times of 8 bits."""
    return 64 * NS_PER_S // baud


class Wire:
    """A chain whose host line is driven in virtual time; collects what the motor sends."""

    def __init__(self, motors: int = 1, **params: Any) -> None:
        self.chain = Chain(motors=motors)
        self.kernel = self.chain.kernel
        self.out = bytearray()
        self.events: list[Event] = []
        self.chain.host_line.add_listener(self.out.extend)
        self.chain.subscribe(self.events.append)
        for key, value in params.items():   # e.g. K81_1=1
            k, motor = key[1:].split("_")
            self.chain.set_param(int(motor), int(k), value)

    def send(self, data: bytes) -> None:
        self.chain.host_line.feed(data)

    def idle(self, duration_ns: int = ms(20)) -> None:
        self.kernel.run(until=self.kernel.now + duration_ns)

    def transact(self, data: bytes, wait_ns: int = ms(20)) -> bytes:
        """Send ``data`` as one burst, let the line go silent, return what came back."""
        self.out.clear()
        self.send(data)
        self.idle(wait_ns)
        reply = bytes(self.out)
        self.out.clear()
        return reply

    def text(self, line: str) -> str:
        """Send a text line (RS-232 mode); return what came back as text."""
        return self.transact(line.encode() + b"\r").decode("latin-1")


@contextlib.contextmanager
def socat_pty_pair(directory: Path) -> Iterator[tuple[str, str]]:
    """Two linked pseudo-terminals made by socat (an independent wire); yields their paths."""
    directory.mkdir(parents=True, exist_ok=True)
    a, b = directory / "pty-a", directory / "pty-b"
    proc = subprocess.Popen(["socat", f"PTY,link={a},raw,echo=0", f"PTY,link={b},raw,echo=0"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        assert wait_until(lambda: a.exists() and b.exists() or proc.poll() is not None), \
            "socat made no ptys"
        assert proc.poll() is None, "socat ended"
        yield str(a), str(b)
    finally:
        proc.terminate()
        proc.wait(5)


#: The name tests/test_modbus_peers.py imports: the suite's one wall-clock wait.
wait_for = wait_until
