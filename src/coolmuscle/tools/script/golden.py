"""A run written back as a golden transcript, as it goes (``coolmuscle run --record``,
:meth:`~coolmuscle.tools.script.runner.RunResult.to_script`; docs/scripts.md).

The text is the script's lines in order, without its ``<<`` lines, each step followed by
``<<`` lines of what was received while it ran (split at CR, LF or CR LF, a piece cut
where the step ended), and after the last step the ``@wait`` of the ``--until`` tail
and what came in it.  :class:`GoldenWriter` writes it a line at a time as the run goes:
what a step received is written as soon as a line of it is whole, so a run of any
length is recorded in bounded memory.  A CR is held until the next byte says whether
an LF follows (the two are one line end).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from typing import Protocol

from .record import escape


class ScriptLine(Protocol):
    """What the writer reads of a script's line (a runner ``Step``)."""

    @property
    def kind(self) -> str: ...
    @property
    def line_no(self) -> int: ...
    @property
    def source(self) -> str: ...


class ScriptLines(Protocol):
    """What the writer reads of a script (a runner ``Script``)."""

    @property
    def lines(self) -> Sequence[ScriptLine]: ...

#: A line with its end (CR LF, CR or LF), or the unfinished rest.
_PIECE = re.compile(rb"[^\r\n]*(?:\r\n|\r|\n)|[^\r\n]+$")


def split_lines(data: bytes) -> list[bytes]:
    """Split at CR, LF or CRLF, keeping the terminators; the last piece may be partial."""
    return [p for p in _PIECE.findall(data) if p]


class GoldenWriter:
    """Writes a run of ``script`` as a golden transcript to ``write`` (a line at a time,
    each with its newline).

    The runner tells it, in order: :meth:`step` before each step it runs, :meth:`received`
    with every byte the motor sends, :meth:`mark` when a step (not an expectation) has
    run, :meth:`tail` before the ``--until`` tail, :meth:`finish` at the end.  When
    ``write`` raises, nothing more is written and the exception is kept in
    :attr:`error` (the run goes on)."""

    def __init__(self, script: ScriptLines, write: Callable[[str], object]) -> None:
        self._lines = [line for line in script.lines if line.kind != "expect"]
        self._next = 0                      # the first script line not written yet
        self._write = write
        self._pending = bytearray()         # received, not yet written: no line end yet
        self.error: Exception | None = None

    def _out(self, text: str) -> None:
        if self.error is None:
            try:
                self._write(text + "\n")
            except Exception as exc:       # the file's failure, not the run's
                self.error = exc

    def _lines_to(self, line_no: float) -> None:
        lines = self._lines
        while self._next < len(lines) and lines[self._next].line_no <= line_no:
            self._out(lines[self._next].source)
            self._next += 1

    def step(self, line_no: int) -> None:
        """A step begins: the script's lines up to it (its own included)."""
        self._lines_to(line_no)

    def received(self, data: bytes) -> None:
        """Bytes the motor sent: each whole line is written; the rest is held."""
        self._pending += data
        pieces = split_lines(bytes(self._pending))
        held = pieces.pop() if pieces and not pieces[-1].endswith(b"\n") else b""
        for piece in pieces:
            self._out(f"<< {escape(piece)}")
        self._pending = bytearray(held)

    def mark(self) -> None:
        """A step has run: what it received is written whole, a line cut short too."""
        for piece in split_lines(bytes(self._pending)):
            self._out(f"<< {escape(piece)}")
        self._pending.clear()

    def tail(self, seconds: float) -> None:
        """The ``--until`` tail begins: the script's remaining lines and its ``@wait``."""
        self._lines_to(float("inf"))
        if seconds > 0:
            self._out(f"@wait {_fmt_seconds(seconds)}")

    def finish(self) -> None:
        """The run has ended: the script's remaining lines and what is still held."""
        self._lines_to(float("inf"))
        self.mark()


def _fmt_seconds(value: float) -> str:
    return f"{value:.9f}".rstrip("0").rstrip(".") or "0"
