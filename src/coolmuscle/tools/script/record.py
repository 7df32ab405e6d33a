"""A run's transcript as it happens: its entries, their text, the recorder of the bytes
received (docs/scripts.md).

Compiled with mypyc (:data:`coolmuscle._accel.MODULES`): every line a motor sends (a
status report ``Ux.1=8``, a reply) goes through :meth:`Recorder.on_bytes`, becomes a
:class:`TranscriptEntry` and, in ``coolmuscle run``, a line printed by
:class:`LineWriter`; interpreted, that cost more than a tenth of a move of the 15-motor
run (docs/performance.md).  Plain typed Python, the same as sources.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final, Literal

from ...sim.kernel import to_seconds

#: ``>`` sent, ``<`` received, ``#`` a note (a wire fault, docs/wire-faults.md)
Direction = Literal[">", "<", "#"]

#: Bytes that :func:`escape` shows as themselves: printable ASCII but the backslash.
_PLAIN: Final = re.compile(rb"[\x20-\x5b\x5d-\x7e]*")
#: Every byte (as a latin-1 character) -> how :func:`escape` writes it.
_ESCAPED: Final = {code: ("\\\\" if code == 92 else chr(code) if 32 <= code < 127
                          else {13: "\\r", 10: "\\n", 9: "\\t"}.get(code, f"\\x{code:02x}"))
                   for code in range(256)}


def escape(data: bytes) -> str:
    """Inverse of :func:`~coolmuscle.tools.script.runner.unescape`: printable ASCII as
    is, everything else escaped."""
    if _PLAIN.fullmatch(data):          # a report or a reply: nothing to escape
        return data.decode("ascii")
    return data.decode("latin-1").translate(_ESCAPED)


def strip_end(data: bytes) -> bytes:
    """``data`` without its line end (CR LF, CR or LF)."""
    if data.endswith(b"\r\n"):
        return data[:-2]
    if data.endswith((b"\r", b"\n")):
        return data[:-1]
    return data


#: What :func:`_line_kind` finds: one whole line ended by CR LF, of printable ASCII but
#: the backslash (a report, a reply: :func:`escape` keeps it as it is), one with other
#: bytes, or anything else.
_PLAIN_LINE: Final = 2
_ONE_LINE: Final = 1
_NOT_ONE_LINE: Final = 0


def _line_kind(data: bytes) -> int:
    """:data:`_PLAIN_LINE`, :data:`_ONE_LINE` or :data:`_NOT_ONE_LINE`."""
    end = len(data) - 2
    if end < 0 or data[end] != 13 or data[end + 1] != 10:
        return _NOT_ONE_LINE
    kind = _PLAIN_LINE
    for i in range(end):
        byte = data[i]
        if byte == 13 or byte == 10:
            return _NOT_ONE_LINE
        if byte < 32 or byte > 126 or byte == 92:
            kind = _ONE_LINE
    return kind


#: Below this many nanoseconds (11.6 days) :func:`seconds_text` writes integers.
_EXACT_BELOW: Final = 10**15
#: By the digits of the whole seconds: the spaces before them (11 characters in all).
_SPACES: Final[tuple[str, ...]] = ("", "   ", "  ", " ", "", "", "", "")
#: By the digits of the microseconds: the zeros before them (6 digits).
_ZEROS: Final[tuple[str, ...]] = ("", "00000", "0000", "000", "00", "0", "")


def seconds_text(ns: int) -> str:
    """``f"{to_seconds(ns):11.6f}"``: kernel nanoseconds as seconds with 6 decimals,
    right-aligned in 11 characters.

    Below :data:`_EXACT_BELOW` and off a half microsecond it is written from the
    integer, without formatting a float (5 k instructions): there ``ns / 1e9`` as a
    float is within 6e-11 s of the exact quotient (half its last place), and the
    quotient is at least 1e-9 s from a half microsecond, so the float rounds to the
    same microsecond as the integer.  A half microsecond (``ns % 1000 == 500``) rounds
    as its float falls: formatted as the float."""
    if 0 <= ns < _EXACT_BELOW and ns % 1000 != 500:
        micro = (ns + 500) // 1000
        whole = str(micro // 1_000_000)
        fraction = str(micro % 1_000_000)
        return f"{_SPACES[len(whole)]}{whole}.{_ZEROS[len(fraction)]}{fraction}"
    return f"{to_seconds(ns):11.6f}"


@dataclass(frozen=True, init=False)
class TranscriptEntry:
    """One line sent (``>``), received (``<``) or noted (``#``: a wire fault) at virtual
    time ``time`` (ns)."""

    time: int
    direction: Direction
    data: bytes
    line_no: int | None = None

    def __init__(self, time: int, direction: Direction, data: bytes,
                 line_no: int | None = None) -> None:
        # written out: built on the hot path (docs/architecture.md "Fast code");
        # object.__setattr__ as a frozen dataclass's own __init__ does (mypyc stores the
        # fields directly)
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "direction", direction)
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "line_no", line_no)

    def __reduce__(self) -> tuple[type[TranscriptEntry],
                                  tuple[int, Direction, bytes, int | None]]:
        # pickle (a run's result sent back by a worker): built again by __init__; mypyc's
        # default would set the fields one by one, which a frozen class refuses
        return TranscriptEntry, (self.time, self.direction, self.data, self.line_no)

    def format(self) -> str:
        """``   1.100000 < Ux.1=8``: seconds, direction, bytes without their line end (a
        ``#`` note as its text)."""
        if self.direction == "#":
            return f"{seconds_text(self.time)} # {self.data.decode('utf-8', 'replace')}"
        return f"{seconds_text(self.time)} {self.direction} {escape(strip_end(self.data))}"


class LineWriter:
    """An ``on_entry`` for a live display: each entry's :meth:`~TranscriptEntry.format`
    and a newline to ``write`` (``coolmuscle run``: ``sys.stdout.write``)."""

    def __init__(self, write: Callable[[str], object]) -> None:
        self.write = write

    def __call__(self, entry: TranscriptEntry) -> None:
        self.write(entry.format() + "\n")

    def received(self, time: int, text: str) -> None:
        """What :meth:`__call__` writes for the entry of a line received at ``time`` whose
        bytes, without their CR LF, are ``text``: printable ASCII but the backslash."""
        self.write(f"{seconds_text(time)} < {text}\n")


class Recorder:
    """Listens to the host line: the entries, the complete lines and the byte stream.

    ``on_entry`` is called with every entry as it is made (``None``: nobody); when it
    raises, it is not called again and the exception is kept in :attr:`display_error`.
    ``on_line`` is called with every complete line received, without its end.

    ``keep`` (the default) keeps every entry in :attr:`entries` and every line in
    :attr:`lines`; without it nothing is kept but what :attr:`stream_limit` allows,
    so a run of any length records in bounded memory (``coolmuscle run``: the entries
    go to the display as they come).  :attr:`received` counts every byte."""

    def __init__(self, kernel: Any, on_entry: Callable[[TranscriptEntry], None] | None,
                 *, keep: bool = True, on_line: Callable[[str], None] | None = None) -> None:
        self.kernel = kernel
        self.on_entry = on_entry
        self.on_line = on_line
        self.keep = keep
        #: The bytes received, up to :attr:`stream_limit` of them (-1: all of them).
        self.stream = bytearray()
        self.stream_limit = -1
        self.received = 0
        self.entries: list[TranscriptEntry] = []
        self.lines: list[str] = []   # complete received lines, without terminator (keep)
        self._line = bytearray()
        self._held: TranscriptEntry | None = None  # a CR-ended line that may get its LF
        self.display_error: Exception | None = None
        #: ``on_entry`` when it is a :class:`LineWriter`: given a plain line's text at once
        self._writer = on_entry if type(on_entry) is LineWriter else None

    def emit(self, entry: TranscriptEntry) -> None:
        if self.keep:
            self.entries.append(entry)
        if self.on_entry is not None:
            try:
                self.on_entry(entry)
            except Exception as exc:  # the display's failure, not the motor's: re-raised later
                self._display_failed(exc)

    def _display_failed(self, exc: Exception) -> None:
        self.display_error = exc
        self.on_entry = self._writer = None

    def flush_held(self) -> None:
        if self._held is not None:
            held, self._held = self._held, None
            self.emit(held)

    def _got_line(self, text: str) -> None:
        if self.keep:
            self.lines.append(text)
        if self.on_line is not None:
            self.on_line(text)

    def on_bytes(self, data: bytes) -> None:
        now: int = self.kernel.now
        self.received += len(data)
        limit = self.stream_limit
        if limit < 0 or len(self.stream) < limit:
            self.stream += data
        kind = _line_kind(data) if self._held is None and not self._line else _NOT_ONE_LINE
        if kind != _NOT_ONE_LINE:
            # one whole CR LF line (a report, a reply): what the loop below makes of it
            text = data[:-2].decode("latin-1")
            self._got_line(text)
            writer = self._writer
            if writer is None or kind != _PLAIN_LINE:
                # the host line's own bytes (a buffer would be copied)
                self.emit(TranscriptEntry(now, "<", data if type(data) is bytes
                                          else bytes(data)))
                return
            if self.keep:
                self.entries.append(TranscriptEntry(now, "<", data if type(data) is bytes
                                                    else bytes(data)))
            try:
                writer.received(now, text)      # what writer(entry) would write
            except Exception as exc:
                self._display_failed(exc)
            return
        for byte in data:
            if byte == 0x0A and self._held is not None and not self._line:
                held, self._held = self._held, None
                # joined, never ``+``: compiled, mypyc 1.19 leaks the left operand of
                # bytes + bytes (docs/performance.md "Compiled hot modules")
                self.emit(TranscriptEntry(held.time, "<", b"".join((held.data, b"\n"))))
                continue
            self.flush_held()
            self._line.append(byte)
            if byte in (0x0D, 0x0A):
                entry = TranscriptEntry(now, "<", bytes(self._line))
                self._got_line(self._line[:-1].decode("latin-1"))
                self._line.clear()
                if byte == 0x0D:
                    self._held = entry
                else:
                    self.emit(entry)

    def sent(self, entry: TranscriptEntry) -> None:
        self.flush_held()
        self.emit(entry)

    def note(self, text: str) -> None:
        """A ``#`` entry now: what a wire fault did to the bytes (after what came before)."""
        self.flush_held()
        self.emit(TranscriptEntry(self.kernel.now, "#", text.encode("utf-8", "replace")))

    def finish(self) -> None:
        self.flush_held()
        if self._line:  # a partial line at the end of the run
            self.emit(TranscriptEntry(self.kernel.now, "<", bytes(self._line)))
            self._line.clear()
