"""A ``coolmuscle sim --pty --pace`` stand-in for a real motor, run as a subprocess, and
raw pyserial exchanges with it (tests/test_desk_*.py)."""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import serial

if TYPE_CHECKING:
    from coolmuscle.tools.desk import DeskLine

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "COLUMNS": "200"}


class StandIn:
    """``coolmuscle sim ARGS`` until :meth:`stop`: its pty path and TCP address."""

    def __init__(self, args: list[str], log: Path) -> None:
        self.log = log
        with log.open("w") as out:
            self.proc = subprocess.Popen([sys.executable, "-m", "coolmuscle", "sim", *args],
                                         stdout=out, stderr=subprocess.STDOUT,
                                         stdin=subprocess.DEVNULL, env=ENV)
        banner = self._wait_for(r"ready\n(.*)\n")
        pty = re.search(r"pty: (/dev/\S+)", banner)
        tcp = re.search(r"tcp: (127\.0\.0\.1:\d+)", banner)
        self.pty = pty.group(1) if pty else ""
        self.tcp = tcp.group(1) if tcp else ""

    def _wait_for(self, pattern: str, seconds: float = 90) -> str:
        deadline = time.monotonic() + seconds
        while True:
            match = re.search(pattern, self.log.read_text())
            if match is not None:
                return match.group(0)
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise AssertionError(f"{pattern!r} not printed:\n{self.log.read_text()}")
            time.sleep(0.05)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)


@contextlib.contextmanager
def stand_in(tmp: Path, *args: str) -> Iterator[StandIn]:
    """Run a stand-in for the duration of a ``with`` (always torn down)."""
    sim = StandIn(list(args), tmp / f"sim-{time.monotonic_ns()}.log")
    try:
        yield sim
    finally:
        sim.stop()


def exchange(path: str, lines: list[str], baud: int = 38400, quiet: float = 0.3,
             limit: float = 10.0) -> list[bytes]:
    """Send each line (CR-ended) at ``baud`` and read what comes back until the line is
    quiet for ``quiet`` s: the bytes received for each, in order."""
    answers: list[bytes] = []
    with serial.Serial(path, baudrate=baud, timeout=0.05) as port:
        port.reset_input_buffer()
        for line in lines:
            port.write(line.encode("latin-1") + b"\r")
            answers.append(read_quiet(port, quiet, limit))
    return answers


def read_quiet(port: serial.Serial, quiet: float = 0.3, limit: float = 10.0) -> bytes:
    got = bytearray()
    start = last = time.monotonic()
    while time.monotonic() - last < quiet and time.monotonic() - start < limit:
        chunk = port.read(4096)
        if chunk:
            got += chunk
            last = time.monotonic()
    return bytes(got)


def virtual_line(setup: list[str], motors: int = 1, firmware: str = "cm2") -> DeskLine:
    """A desk line to an in-process virtual chain (``coolmuscle://?mode=fast``) after the
    ``setup`` lines were typed on it."""
    from coolmuscle.client.banks import send_line
    from coolmuscle.tools.desk import DeskLine

    line = DeskLine(f"coolmuscle://?motors={motors}&firmware={firmware}&mode=fast")
    for text in setup:
        line.run(send_line(line.session, 1, text))
    return line
