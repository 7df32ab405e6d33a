"""What the motor says, line by line: classification and typed values (sans-IO).

This module owns how the host library reads the motor's lines, as cml-users-guide.txt
prints them:

* 6.6 query replies ``NAME.n=VALUE`` (``Px.1=10000``, ``OUT.1=03``, ``K23.1=1``,
  ``P15.1=100``, ``V1.1="abcd"``) and comma-separated listings (``?90``, ``?A``, ``?.n``);
* the ``?85`` version title ``ID1 : CM2v3.10R.1 #0802A12345``;
* ch. 3 K23 reports: ``Ux.n=`` (function 1), ``IN.n=`` (2), ``OUT.n=`` (4) and the
  messages of function 16 (``errorNN.n: ...``, ``saved.n``, ``End.n``, ``[End of Bank]``).

Nothing here does I/O or keeps state; :mod:`coolmuscle.client.protocol` uses it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final, Literal

from ..errors import MotorError, ProtocolError, motor_error

__all__ = ["Received", "LineKind", "classify", "parse_assignment", "parse_listing",
           "Version", "parse_version", "parse_io_word", "parse_int_reply"]

LineKind = Literal["status", "input", "output", "error", "message", "value", "listing",
                   "version", "text", "garbled"]

#: ``NAME.n=VALUE``: a 6.6 reply or a K23 report; NAME keeps its memory number (P15).
_ASSIGN_RE: Final = re.compile(r"([A-Za-z][A-Za-z0-9]*)\.(\d+)=(.*)")
#: ``errorNN.n: text`` (ch. 3 K23 function 16).
_ERROR_RE: Final = re.compile(r"error(\d{2})\.(\d+):\s?(.*)")
#: ``?85``: ``ID1 : CM2v3.10R.1 #0802A12345`` (6.6).
_VERSION_RE: Final = re.compile(
    r"ID(\d+) : ([A-Z0-9]+)v(\d+\.\d+)([A-Z])\.(\w+) #(\S+)")
#: Messages of K23 function 16 and of 2.1.2 (``saved.n``, ``End.n``, ``Can't back!``).
_MESSAGE_RE: Final = re.compile(
    r"(saved\.(\d+)|End\.(\d+)|\[End of Bank\]|Can't back!|Change Baud Rate.*)")
_EVENT_NAMES: Final = {"Ux": "status", "IN": "input", "OUT": "output"}
_INT_RE: Final = re.compile(r"-?\d+")
_HEX_RE: Final = re.compile(r"[0-9A-Fa-f]{1,4}")


@dataclass(frozen=True, slots=True)
class Received:
    """One line from the motor, classified.

    ``name`` is the reply's name with its memory number (``"Px"``, ``"K23"``,
    ``"P15"``, ``"OUT1"``), ``motor`` the ID after the dot, ``value`` the text
    after ``=`` (``None`` for lines of other shapes).
    """

    text: str
    kind: LineKind
    motor: int | None = None
    name: str | None = None
    value: str | None = None

    def error(self) -> MotorError:
        """The exception an ``errorNN.n`` line stands for."""
        match = _ERROR_RE.fullmatch(self.text)
        if match is None:
            raise ValueError(f"not an error line: {self.text!r}")
        return motor_error(int(match.group(1)), match.group(3), int(match.group(2)))

    def int_value(self) -> int:
        """``value`` as an integer, or :class:`ProtocolError` (a garbled reply)."""
        if self.value is None or not _INT_RE.fullmatch(self.value.strip()):
            raise ProtocolError(f"garbled reply {self.text!r}: expected an integer after '='")
        return int(self.value)


def _printable(text: str) -> bool:
    return all(" " <= ch <= "~" for ch in text)


def classify(raw: bytes) -> Received:
    """Classify one line (without its CR/LF) as the motor prints it (6.6, ch. 3 K23)."""
    text = raw.decode("latin-1")
    if not text or not _printable(text):
        return Received(text, "garbled")
    match = _ERROR_RE.fullmatch(text)
    if match:
        return Received(text, "error", int(match.group(2)), f"error{match.group(1)}",
                        match.group(3))
    match = _MESSAGE_RE.fullmatch(text)
    if match:
        motor = match.group(2) or match.group(3)
        return Received(text, "message", int(motor) if motor else None)
    if ", " in text and text.count("=") > 1:
        first = _ASSIGN_RE.match(text)
        return Received(text, "listing", int(first.group(2)) if first else None)
    match = _ASSIGN_RE.fullmatch(text)
    if match:
        name, motor, value = match.group(1), int(match.group(2)), match.group(3)
        kind = _EVENT_NAMES.get(name, "value")
        return Received(text, kind, motor, name, value)  # type: ignore[arg-type]
    match = _VERSION_RE.fullmatch(text)
    if match:
        return Received(text, "version", int(match.group(1)))
    return Received(text, "text")


def parse_assignment(text: str) -> tuple[str, int, str]:
    """``"P15.1=100"`` -> ``("P15", 1, "100")``; :class:`ProtocolError` otherwise."""
    match = _ASSIGN_RE.fullmatch(text.strip())
    if match is None:
        raise ProtocolError(f"garbled reply {text!r}: expected NAME.n=VALUE")
    return match.group(1), int(match.group(2)), match.group(3)


def parse_listing(lines: list[str]) -> dict[str, str]:
    """``?90`` / ``?A`` / ``?.n`` lines (``", "`` between items) -> ``{name: value}``.

    Names keep their memory number and drop the motor ID (``K23``, ``A1``, ``P``).
    """
    items: dict[str, str] = {}
    for line in lines:
        for item in line.split(","):
            if item.strip():
                name, _motor, value = parse_assignment(item)
                items[name] = value
    return items


def parse_int_reply(line: Received, name: str, motor: int) -> int:
    """The integer of a ``NAME.n=VALUE`` reply, checking name and motor ID."""
    if line.name != name or line.motor != motor:
        raise ProtocolError(f"unexpected reply {line.text!r} (expected {name}.{motor}=...)")
    return line.int_value()


def parse_io_word(line: Received) -> int:
    """``IN.1=1C`` / ``OUT.1=03``: hexadecimal, bit 0 = input/output 1 (6.6 ?70, ?50)."""
    value = (line.value or "").strip()
    if not _HEX_RE.fullmatch(value):
        raise ProtocolError(f"garbled reply {line.text!r}: expected hexadecimal digits")
    return int(value, 16)


@dataclass(frozen=True, slots=True)
class Version:
    """The ``?85`` version title, field by field (6.6 ?85)."""

    motor: int
    series: str
    firmware: str
    motor_type: str
    hardware: str
    serial: str
    text: str

    def profile(self) -> str:
        """The coolmuscle firmware profile this title suggests: cm2, cm1 or rt3.

        CM2 series -> ``cm2``; CM1 series with type C -> ``cm1``; other CM1 -> ``rt3``
        (docs/fidelity.md "Host library and tools").
        """
        if self.series.upper() == "CM2":
            return "cm2"
        return "cm1" if self.motor_type.upper() == "C" else "rt3"


def parse_version(text: str) -> Version:
    """``"ID1 : CM2v3.10R.1 #0802A12345"`` -> :class:`Version` (6.6 ?85)."""
    match = _VERSION_RE.fullmatch(text.strip())
    if match is None:
        raise ProtocolError(f"garbled version title {text!r}")
    motor, series, firmware, kind, hardware, serial = match.groups()
    return Version(int(motor), series, firmware, kind, hardware, serial, text.strip())
