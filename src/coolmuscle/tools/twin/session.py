"""Reading a capture (``coolmuscle capture``'s ``.cml`` file) into what the twin needs.

A capture is a script in the golden-transcript format of ``coolmuscle run``
(docs/scripts.md) whose comment lines carry the real instants (docs/twin.md "The
capture file"):

* line 1 ``# coolmuscle capture: port=... baud=38400 parity=none echo=on started=...``
  (how the twin recognises a capture; any other ``.cml`` file is refused, since without
  the instants there is nothing to compare the timing with);
* ``# chain: motors=N firmware=cm2 [machine=FILE]`` when known;
* ``# t=SECONDS >`` immediately before each line the host sent (a command line or an
  ``@send``), ``# t=SECONDS <`` before each ``<<`` line (an ``@until`` may stand
  between them): seconds since the capture started;
* ``# end: key=value ...`` when the capture ended cleanly (a capture cut short lacks it).

:func:`read_session` returns a :class:`Session`: the lines sent and received with their
real instants, and the polled values (6.6: ``?95`` Pe, ``?96`` Px, ``?97`` Sx, ``?98``
Ix).  Anything that does not fit is one :class:`CaptureError` naming the line.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from ..script.runner import MAX_SECONDS, Script, ScriptError, parse_script

__all__ = ["CaptureError", "Line", "Poll", "Session", "POLLED", "parse_poll", "parse_session",
           "read_session"]

#: The reply prefix of each polled quantity -> its query and unit (6.6).
POLLED: dict[str, tuple[str, str]] = {"Pe": ("?95", "pulses"), "Px": ("?96", "pulses"),
                                      "Sx": ("?97", "speed units"), "Ix": ("?98", "% rated")}
CAPTURE_MARK = "# coolmuscle capture:"
FIRMWARES = ("cm2", "rt3", "cm1")

_STAMP = re.compile(r"# t=([0-9]+(?:\.[0-9]*)?) ([<>])\Z")
_POLL = re.compile(r"(Px|Pe|Sx|Ix)\.([0-9]{1,2})=(-?[0-9]{1,12})\Z")
#: A capture bigger than this is refused (an hour at 38.4 kbps is about 30 MB).
MAX_BYTES = 256 * 1024 * 1024


class CaptureError(ScriptError):
    """A file that is not a capture, or a capture that does not hold together (exit 2)."""


@dataclass(frozen=True, slots=True)
class Line:
    """A line sent (``>``) or received (``<``) at ``time`` seconds after the capture began."""

    time: float
    direction: Literal[">", "<"]
    data: bytes
    line_no: int            # where it is written in the capture file

    @property
    def text(self) -> str:
        """The bytes without their line end (latin-1: every byte is one character)."""
        return self.data.rstrip(b"\r\n").decode("latin-1")


@dataclass(frozen=True, slots=True)
class Poll:
    """A polled value: the reply ``Px.1=10000`` to ``?96.1``."""

    motor: int
    quantity: str           # Px, Pe, Sx, Ix
    value: int
    time: float             # the reply's last byte reached the relay
    asked: float            # the line sent before it (the query) reached the relay
    sent_index: int         # index in Session.sent of that line (-1: none)
    received_index: int     # index in Session.received


@dataclass
class Session:
    """A capture: header, lines sent and received with their real instants, polls."""

    source: str
    header: dict[str, str]
    script: Script
    sent: list[Line]
    received: list[Line]
    motors: int = 1
    firmware: str = "cm2"
    machine: Path | None = None
    end: dict[str, str] | None = None
    polls: list[Poll] = field(default_factory=list)

    @property
    def baud(self) -> int | None:
        value = self.header.get("baud", "")
        return int(value) if value.isdigit() and int(value) > 0 else None

    @property
    def bits_per_byte(self) -> int:
        """Start + 8 data + stop bits, and a parity bit unless parity=none."""
        return 10 if self.header.get("parity", "none") == "none" else 11

    @property
    def duration(self) -> float:
        """Seconds from the start to the last line sent or received."""
        last = [lines[-1].time for lines in (self.sent, self.received) if lines]
        return max(last, default=0.0)

    def sent_before(self) -> list[int]:
        """For each line received: the index in :attr:`sent` of the last line sent
        before it in the file (-1: none yet)."""
        out: list[int] = []
        j = -1
        for line in self.received:
            while j + 1 < len(self.sent) and self.sent[j + 1].line_no < line.line_no:
                j += 1
            out.append(j)
        return out

    def k_params(self) -> dict[int, int]:
        """K values the capture header gives (``k23=``, ``k20=``)."""
        out: dict[int, int] = {}
        for key, value in self.header.items():
            if re.fullmatch(r"k[0-9]{2}", key):
                out[int(key[1:])] = int(value)
        return out


def parse_poll(text: str) -> tuple[str, int, int] | None:
    """``"Px.1=10000"`` -> ``("Px", 1, 10000)``; ``None`` for any other line."""
    match = _POLL.match(text)
    if match is None:
        return None
    return match.group(1), int(match.group(2)), int(match.group(3))


def read_session(path: str | os.PathLike[str]) -> Session:
    """Read a capture file (:class:`CaptureError` for anything that is not one)."""
    path = Path(path)
    try:
        if path.is_char_device() or path.is_block_device() or path.is_fifo():
            raise CaptureError(f"cannot read {path}: a device, not a capture file")
        if path.is_dir():
            raise CaptureError(f"cannot read {path}: a directory, not a capture file")
        if path.stat().st_size > MAX_BYTES:
            raise CaptureError(f"{path}: larger than {MAX_BYTES >> 20} MB: not a capture")
        data = path.read_bytes()
    except OSError as exc:
        raise CaptureError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise CaptureError(f"{path}: not a capture (not UTF-8 text, byte {exc.start})") from None
    session = parse_session(text, str(path))
    if session.machine is not None and not session.machine.is_absolute():
        session.machine = path.parent / session.machine
    return session


def _pairs(text: str, where: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in text.split():
        key, eq, value = item.partition("=")
        if not eq or not key:
            raise CaptureError(f"{where}: {item!r} is not key=value")
        out[key.lower()] = value
    return out


def _header(first: str, source: str) -> dict[str, str]:
    if not first.startswith(CAPTURE_MARK):
        raise CaptureError(f"{source}: not a capture: its first line is not "
                           f"'{CAPTURE_MARK} ...' (docs/twin.md; coolmuscle capture "
                           "writes one)")
    header = _pairs(first[len(CAPTURE_MARK):], f"{source} line 1")
    checks = {"baud": r"[0-9]{1,7}", "parity": r"none|even|odd", "echo": r"on|off|unknown",
              "motors": r"[0-9]{1,2}"}
    for key, pattern in checks.items():
        if key in header and not re.fullmatch(pattern, header[key]):
            raise CaptureError(f"{source} line 1: {key}={header[key]} is not {pattern}")
    for key, value in header.items():
        if re.fullmatch(r"k[0-9]{2}", key) and not re.fullmatch(r"-?[0-9]{1,10}", value):
            raise CaptureError(f"{source} line 1: {key}={value} is not a whole number")
    return header


def _chain(session: Session, line: str, source: str, line_no: int) -> None:
    where = f"{source} line {line_no}"
    items = _pairs(line.split(":", 1)[1], where)
    motors = items.get("motors", session.header.get("motors"))
    if motors is not None:
        if not (motors.isdigit() and 1 <= int(motors) <= 15):
            raise CaptureError(f"{where}: motors={motors} is not 1..15")
        session.motors = int(motors)
    firmware = items.get("firmware", session.firmware).lower()
    if firmware not in FIRMWARES:
        raise CaptureError(f"{where}: firmware={firmware} is not cm2, rt3 or cm1")
    session.firmware = firmware
    if items.get("machine"):
        session.machine = Path(items["machine"])


def parse_session(text: str, source: str = "<capture>") -> Session:
    """Parse capture text (see the module docstring); :class:`CaptureError` if it is not one."""
    first = text.split("\n", 1)[0].removesuffix("\r")
    header = _header(first, source)
    try:
        script = parse_script(text)
    except CaptureError:
        raise
    except ScriptError as exc:
        raise CaptureError(f"{source}: {exc}") from None
    session = Session(source, header, script, [], [])
    if "motors" in header:
        if not 1 <= int(header["motors"]) <= 15:
            raise CaptureError(f"{source} line 1: motors={header['motors']} is not 1..15")
        session.motors = int(header["motors"])
    pending: tuple[float, str, int] | None = None     # (seconds, direction, line)
    last = {">": 0.0, "<": 0.0}

    def fail(line_no: int, message: str) -> CaptureError:
        return CaptureError(f"{source} line {line_no}: {message}")

    for step in script.lines:
        if step.kind == "comment":
            if step.source.startswith("# t="):
                match = _STAMP.match(step.source)
                if match is None:
                    raise fail(step.line_no, f"bad time stamp {step.source!r} (expected "
                                             "'# t=SECONDS >' or '# t=SECONDS <')")
                if pending is not None:
                    raise fail(pending[2], "a time stamp not followed by its line")
                seconds = float(match.group(1))
                if not (math.isfinite(seconds) and seconds <= MAX_SECONDS):
                    raise fail(step.line_no, f"t={match.group(1)} is beyond {MAX_SECONDS:g} s")
                direction = match.group(2)
                if seconds < last[direction]:
                    raise fail(step.line_no, f"t={match.group(1)} goes back in time (the line "
                                             f"{'sent' if direction == '>' else 'received'} "
                                             f"before it: t={last[direction]:.6f})")
                last[direction] = seconds
                pending = (seconds, direction, step.line_no)
            elif step.source.lower().startswith("# chain:"):
                _chain(session, step.source, source, step.line_no)
            elif step.source.startswith("# end:"):
                session.end = _pairs(step.source[len("# end:"):], f"{source} line "
                                     f"{step.line_no}")
            continue
        if step.kind in ("send", "raw"):
            if pending is None or pending[1] != ">":
                raise fail(step.line_no, "a line sent without its '# t=SECONDS >' stamp "
                                         "just before it")
            session.sent.append(Line(pending[0], ">", step.data, step.line_no))
            pending = None
        elif step.kind == "expect":
            if pending is None or pending[1] != "<":
                raise fail(step.line_no, "a line received without its '# t=SECONDS <' stamp "
                                         "before it")
            session.received.append(Line(pending[0], "<", step.data, step.line_no))
            pending = None
        elif step.kind == "until":
            if pending is not None and pending[1] != "<":
                raise fail(pending[2], "a '>' stamp must stand just before the line sent")
        elif step.kind == "wait":
            if pending is not None:
                raise fail(pending[2], "a time stamp not followed by its line")
        else:       # @input, @analog: a relay sees the line, not the wiring
            raise fail(step.line_no, f"{step.source.split()[0]} has no place in a capture "
                                     "(a relay records the host line only)")
    if pending is not None:
        raise fail(pending[2], "a time stamp not followed by its line")
    session.polls = _polls(session)
    return session


def _polls(session: Session) -> list[Poll]:
    """The polled values, each with the line sent before it (its query)."""
    out: list[Poll] = []
    for i, (line, j) in enumerate(zip(session.received, session.sent_before(), strict=True)):
        found = parse_poll(line.text)
        if found is None:
            continue
        quantity, motor, value = found
        asked = session.sent[j].time if j >= 0 else line.time
        out.append(Poll(motor, quantity, value, line.time, min(asked, line.time), j, i))
    return out
