"""Test doubles for the front-end tests: a fake chain with the real HostLine.

``FakeChain`` has the final ``Chain`` constructor and attributes (``kernel``,
``host_line``, ``motor_ids``, ``subscribe()`` (no events), ``close()``) and a tiny line
callback, so transports, pacing and the script runner are exercised with the real
echo / delimiter / pacing behaviour of :class:`coolmuscle.device.hostline.HostLine`
until the motor model lands:

* ``?96.n``   -> ``Px.n=<counter>`` (counter starts at 1, one per reply, all motors);
* ``^.n``     -> ``Ux.n=8`` after ``move_time`` seconds of virtual time (kernel event);
* ``K23.n=v`` -> echo off when v has bit 8; ``K70.n=v`` -> delimiter CR (0) / CRLF (1);
  ``K20.n=v`` -> baud rate (for pacing);
* ``boom``    -> raises ``RuntimeError`` (a model bug; front ends must survive it).

Also ``play_over_serial``: plays a script (docs/scripts.md) over any pyserial port,
checking ``<<`` expectations as exact bytes, with wall-clock timeouts.
"""

from __future__ import annotations

import re
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from coolmuscle.device.hostline import BAUD_RATES, HostLine, LineSettings
from coolmuscle.sim.kernel import Kernel, seconds
from coolmuscle.tools.script.runner import parse_script

_QUERY = re.compile(r"\?96\.(\d+)")
_GO = re.compile(r"\^\.(\d+)")
_K = re.compile(r"K(\d+)\.(\d+)=(-?\d+)")


class FakeChain:
    """A chain stand-in that answers a few lines (see module docstring)."""

    def __init__(self, kernel: Kernel | None = None, motors: int = 1, *,
                 firmware: str = "cm2", state_dir: Path | str | None = None,
                 pacing: bool = False, move_time: float = 1.1) -> None:
        self.kernel = kernel or Kernel()
        self.settings = LineSettings()
        self.host_line = HostLine(self.kernel, self._on_line, lambda: self.settings,
                                  pacing=pacing)
        self.firmware = firmware
        self.state_dir = Path(state_dir) if state_dir else None
        self._motors = motors
        self.move_time = move_time
        self.counter = 0
        self.lines: list[str] = []
        self.closed = False

    @property
    def motor_ids(self) -> tuple[int, ...]:
        return tuple(range(1, self._motors + 1))

    def _on_line(self, text: str) -> None:
        self.lines.append(text)
        if m := _QUERY.fullmatch(text):
            self.counter += 1
            self.host_line.send_line(f"Px.{m.group(1)}={self.counter}")
        elif m := _GO.fullmatch(text):
            motor = m.group(1)
            self.kernel.schedule(seconds(self.move_time),
                                 lambda: self.host_line.send_line(f"Ux.{motor}=8"),
                                 name="fake-move")
        elif m := _K.fullmatch(text):
            k, value = int(m.group(1)), int(m.group(3))
            if k == 23:
                self.settings = replace(self.settings, echo=not value & 8)
            elif k == 70:
                self.settings = replace(self.settings, delimiter=b"\r\n" if value else b"\r")
            elif k == 20 and value in BAUD_RATES:
                self.settings = replace(self.settings, baud=BAUD_RATES[value])
        elif text == "boom":
            raise RuntimeError("fake model failure")

    def subscribe(self, listener: Any) -> Any:
        """The device API's event stream: a fake chain says nothing there."""
        return lambda: None

    def close(self) -> None:
        self.closed = True


def fake_factory(**kwargs: Any) -> Any:
    """A ``Chain``-compatible factory making :class:`FakeChain` with ``kwargs``."""
    def make(kernel: Kernel | None = None, motors: int = 1, **options: Any) -> FakeChain:
        options = {"motors": motors, **options, **kwargs}
        return FakeChain(kernel, **options)
    return make


#: The transcript every transport test plays (FakeChain with move_time=0.2).
ROUNDTRIP = """\
# FakeChain round trip: query, move, event
?96.1
<< ?96.1\\r\\n
<< Px.1=1\\r\\n
S.1=100
<< S.1=100\\r\\n
^.1
<< ^.1\\r\\n
@until Ux\\.1=8 5
<< Ux.1=8\\r\\n
?96.1
<< ?96.1\\r\\n
<< Px.1=2\\r\\n
"""


def play_over_serial(ser: Any, text: str, *, timeout: float = 5.0) -> bytes:
    """Play a script over a pyserial port; raise AssertionError at the first mismatch.

    Expectations are read with a wall-clock ``timeout``; ``@wait`` sleeps; ``@until``
    reads until a received line matches.  Returns every byte received.
    """
    script = parse_script(text)
    received = bytearray()
    check = 0       # next byte to check against an expectation
    scan = 0        # next byte @until looks at

    def read_more(deadline: float) -> bool:
        ser.timeout = max(0.0, min(0.2, deadline - time.monotonic()))
        chunk = ser.read(max(1, ser.in_waiting))
        received.extend(chunk)
        return bool(chunk)

    for step in script.steps:
        if step.kind in ("send", "raw"):
            ser.write(step.data)
        elif step.kind == "wait":
            time.sleep(step.seconds)
        elif step.kind == "until":
            deadline = time.monotonic() + step.seconds
            assert step.pattern is not None
            while True:
                lines = bytes(received[scan:]).splitlines(keepends=True)
                hit = None
                offset = scan
                for line in lines:
                    offset += len(line)
                    if line.endswith((b"\r", b"\n")) and step.pattern.search(
                            line.rstrip(b"\r\n").decode("latin-1")):
                        hit = offset
                        break
                if hit is not None:
                    scan = hit
                    break
                if time.monotonic() > deadline:
                    raise AssertionError(f"line {step.line_no}: @until timed out; "
                                         f"got {bytes(received)!r}")
                read_more(deadline)
        elif step.kind == "expect":
            deadline = time.monotonic() + timeout
            while len(received) < check + len(step.data) and time.monotonic() < deadline:
                read_more(deadline)
            got = bytes(received[check:check + len(step.data)])
            assert got == step.data, (f"line {step.line_no}: expected {step.data!r}, got {got!r} "
                                      f"(all: {bytes(received)!r})")
            check += len(step.data)
    return bytes(received)
