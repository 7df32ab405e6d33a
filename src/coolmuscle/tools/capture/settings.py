"""The line settings of a capture: baud rate, parity, echo, firmware (docs/user-guide.md).

Given on the command line, or found by a short probe before the host program is let
in: three queries the motor answers without changing anything (6.6 ``?85``, ch. 3
``K20.n`` and ``K23.n`` alone, reply ``K23.1=1``).  The probe's bytes are not part of
the session; the header says what it found (``k20=``, ``k23=``).

* baud rate: K20 (0 38.4k, 1 9.6k, 2 19.2k, 3 57.6k, 4 115.2k, 5 230.4k, ch. 3 K20).
  On a serial device (a path, or ``rfc2217://``) whose motor does not answer at the
  rate given, every rate and parity (K82: none, even, odd) is tried in turn; a socket
  or the in-process ``coolmuscle://`` has no wire, one try;
* echo: K23 function 8 is "no local echo" (ch. 3 K23), cross-checked with what came
  back: the echo of the query itself;
* firmware: the ``?85`` title (6.6), as the host library reads it.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from ...client.replies import parse_version
from ...device.hostline import BAUD_RATES
from ...errors import ProtocolError

__all__ = ["PARITIES", "LineSettings", "probe"]

#: ``--parity`` -> pyserial's parity letter (K82: 0 none, 1 even, 2 odd).
PARITIES = {"none": "N", "even": "E", "odd": "O"}
#: Seconds to wait for each reply of the probe (a motor answers within milliseconds).
REPLY_TIMEOUT = 0.5
#: The probe is over once the motor has been quiet this long (its last lines drained).
QUIET = 0.05
_K_REPLY = re.compile(r"^K(20|23)\.1=(-?\d+)$")


@dataclass(frozen=True)
class LineSettings:
    """What the header of a capture says about the line (None: not known)."""

    baud: int = 38400
    parity: str = "none"
    echo: bool | None = None
    k20: int | None = None
    k23: int | None = None
    firmware: str | None = None

    def echo_word(self) -> str:
        return "unknown" if self.echo is None else ("on" if self.echo else "off")


def _is_serial_device(url: str) -> bool:
    """A wire with a baud rate: a device path or ``rfc2217://``."""
    return "://" not in url or url.lower().startswith("rfc2217://")


class _Lines:
    """Complete lines from a pyserial port, with a deadline per call."""

    def __init__(self, port: Any) -> None:
        self.port = port
        self.buffer = bytearray()

    def until(self, wanted: Callable[[str], bool], timeout: float) -> list[str]:
        """Lines read until one satisfies ``wanted`` or ``timeout`` s pass."""
        lines: list[str] = []
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            chunk = self.port.read(max(1, self.port.in_waiting))
            self.buffer += chunk
            while (end := re.search(rb"\r\n|\r|\n", self.buffer)) is not None:
                lines.append(self.buffer[:end.start()].decode("latin-1"))
                del self.buffer[:end.end()]
                if wanted(lines[-1]):
                    return lines
        return lines

    def drain(self, limit: float = 1.0) -> None:
        """Read until the motor is quiet (what the probe made it say is not kept)."""
        deadline = time.monotonic() + limit
        last = time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - last < QUIET:
            if self.port.read(max(1, self.port.in_waiting)):
                last = time.monotonic()
        self.buffer.clear()


def _ask(lines: _Lines, query: str, wanted: Callable[[str], bool]) -> tuple[str | None, bool]:
    """Send ``query``; its reply line (or None) and whether its echo came back."""
    lines.port.write(query.encode("ascii") + b"\r")
    got = lines.until(wanted, REPLY_TIMEOUT)
    reply = next((line for line in got if wanted(line)), None)
    return reply, query in got


def _version_profile(line: str) -> str | None:
    try:
        return parse_version(line).profile()
    except ProtocolError:
        return None


def _ask_k(lines: _Lines, number: int) -> int | None:
    """``K20.1`` alone: the value of K20 (``K20.1=0``), or None."""
    def is_reply(text: str) -> bool:
        match = _K_REPLY.match(text)
        return match is not None and match.group(1) == str(number)
    reply, _ = _ask(lines, f"K{number}.1", is_reply)
    return int(reply.split("=")[1]) if reply is not None else None


def _one_try(port: Any, settings: LineSettings, leading_cr: bool) -> LineSettings | None:
    """The settings the motor answers with at the port's rate and parity, or None."""
    lines = _Lines(port)
    port.reset_input_buffer()
    if leading_cr:        # the garbage of a try at another rate ends here as a bad line
        port.write(b"\r")
        lines.drain(0.2)
    version, echoed = _ask(lines, "?85.1", lambda text: _version_profile(text) is not None)
    if version is None:
        return None
    k20, k23 = _ask_k(lines, 20), _ask_k(lines, 23)
    lines.drain()
    echo = not (k23 & 8) if k23 is not None else echoed
    baud = BAUD_RATES.get(k20, settings.baud) if k20 is not None else settings.baud
    return replace(settings, baud=baud, echo=echo, k20=k20, k23=k23,
                   firmware=_version_profile(version))


def probe(port: Any, url: str, settings: LineSettings, *, scan: bool,
          say: Callable[[str], None]) -> LineSettings:
    """Ask the motor on ``port`` (open at ``settings``' rate and parity) what it is set to.

    ``scan``: when it does not answer, try every rate and parity (serial devices only;
    the port is left at the ones that answered).  Returns ``settings`` completed; what
    could not be found stays as given (echo ``None``: unknown)."""
    found = _one_try(port, settings, leading_cr=False)
    if found is not None or not (scan and _is_serial_device(url)):
        if found is None:
            say(f"the motor on {url} did not answer ?85.1; baud rate, parity and echo "
                "are not known (give --baud, --parity, --echo)")
        return found or settings
    say(f"no answer at {settings.baud} bit/s, parity {settings.parity}: trying the others")
    for baud in sorted(BAUD_RATES.values()):
        for parity, letter in PARITIES.items():
            if (baud, parity) == (settings.baud, settings.parity):
                continue
            port.baudrate, port.parity = baud, letter
            tried = replace(settings, baud=baud, parity=parity)
            found = _one_try(port, tried, leading_cr=True)
            if found is not None:
                return found
    port.baudrate, port.parity = settings.baud, PARITIES[settings.parity]
    say(f"the motor on {url} answered at no baud rate and parity; using {settings.baud} "
        f"bit/s, parity {settings.parity}")
    return settings
