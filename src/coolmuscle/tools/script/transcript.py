"""Writing a live session as a golden transcript (docs/scripts.md).

One writer, two users: ``:log FILE`` in ``coolmuscle term`` (:class:`TranscriptRecorder`)
and ``coolmuscle capture`` (:mod:`coolmuscle.tools.capture`, which adds the ``# t=``
stamps and a header; the format is docs/user-guide.md "coolmuscle capture").

:class:`SessionWriter` turns the bytes of both directions, each with the instant it was
seen, into script lines that ``coolmuscle run --check`` replays:

* a line the host sent (ended by its CR) is written as typed; bytes that are not such a
  line (an LF end, control bytes, a line the runner would read as a comment, a directive
  or an expectation, a line cut by a reply that came in the middle) as ``@send`` with
  escapes, so the replay sends exactly the same bytes;
* every line received is a ``<<`` line, exactly as received (escaped).  A received line
  that is not the echo of a line sent is preceded by ``@until ^LINE$ T``: in the replay
  virtual time then runs until the motor says it, as the motor said it after a while
  here (T is twice that wait plus 2 s).  Each ``@until`` consumes lines in order, so a
  report that looks like an earlier reply (``Ux.1=8``) is matched at its own place;
* ``@wait S`` before a line sent brings the replay to the instant it was sent here:
  S is counted from where the replay stands, the last line sent or the last line an
  ``@until`` waited for (an echo takes no virtual time in the replay, so it does not
  count).  Wall seconds: record a real-time session (scale 1).

Received lines end at CR, LF or CRLF as the runner splits them; a CR whose LF has not
come yet is held until the next byte, a byte the other way, or :meth:`SessionWriter.tick`.

A line longer than ``MAX_PIECE`` bytes (without its end) is written in pieces as it
comes, each at most that long: a sent line as ``@send`` pieces, a received line as
``<<`` pieces (no ``@until``: a ``@wait`` brings the replay to when each came), so the
writer's memory does not grow with a line's length (a 64 MiB line without a line end
is 1,024 pieces).  The replay sends and expects the same bytes in the same order.

:class:`LineFile` is where the lines go: whole lines at a time, each written to the
kernel at once (a cut-short session is valid up to its last line); when the disk is
full or fails it says so once, trims what it wrote half and takes no more: the session
goes on, the file is what was written.
"""

from __future__ import annotations

import os
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Literal

from .runner import ScriptError, escape, parse_line

__all__ = ["LineFile", "SessionWriter", "TranscriptRecorder", "until_pattern"]

Direction = Literal[">", "<"]

#: A received line ends here: CRLF, a CR followed by something else, or LF.
_LINE_END = re.compile(rb"\r\n|\r(?=[^\n])|\n")
#: A line sent ends at CR or LF (an LF right after a CR goes out as ``@send \n``).
_SENT_END = re.compile(rb"[\r\n]")
#: Bytes written as themselves in a plain sent line: printable ASCII.
_PRINTABLE = re.compile(rb"[\x20-\x7e]*")
#: Longest piece of one line written at once (bytes, before escaping).
MAX_PIECE = 64 * 1024


#: Every byte (as a latin-1 character) -> how an ``@until`` pattern says it.
_UNTIL_ESCAPED = {code: (chr(code) if chr(code).isalnum() and code < 128
                         else re.escape(chr(code)) if 32 <= code < 127 else f"\\x{code:02x}")
                  for code in range(256)}


def until_pattern(text: bytes) -> str:
    """``^LINE$`` for ``@until``: letters and digits as is, other printable ASCII escaped
    by :func:`re.escape`, everything else as ``\\xNN`` (the file stays ASCII)."""
    return "^" + text.decode("latin-1").translate(_UNTIL_ESCAPED) + "$"


def _plain_line(line: bytes) -> str | None:
    """``line`` (without its CR) as a script line that sends exactly ``line + CR``,
    or ``None`` when only ``@send`` can say it."""
    if not _PRINTABLE.fullmatch(line):
        return None
    text = line.decode("ascii")
    try:
        step = parse_line(text, 1)
    except ScriptError:
        return None
    return text if step.kind == "send" and step.data == line + b"\r" else None


class LineFile:
    """Whole lines appended to ``path`` (created, or emptied), each write at once.

    On an error (``ENOSPC``, ``EIO``) :meth:`write` cuts the file back to its last whole
    line, calls ``on_error`` once with a sentence and writes nothing more."""

    def __init__(self, path: str | os.PathLike[str],
                 on_error: Callable[[str], None] | None = None) -> None:
        self.path = Path(path)
        self.on_error = on_error
        self.error: OSError | None = None
        self.size = 0
        self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC,
                                       0o666)

    def write(self, text: str) -> bool:
        """Append ``text`` (whole lines); False once the file has stopped growing."""
        if self._fd is None or self.error is not None:
            return False
        data = memoryview(text.encode("utf-8"))
        start = self.size
        try:
            while data:
                done = os.write(self._fd, data)
                data = data[done:]
                self.size += done
        except OSError as exc:
            self.error = exc
            self._cut_back(start)
            if self.on_error is not None:
                self.on_error(f"{self.path} stopped growing at {self.size} bytes: "
                              f"{exc.strerror or exc}")
            return False
        return True

    def _cut_back(self, size: int) -> None:
        """Take back the part of the failed write that reached the file."""
        assert self._fd is not None
        self.size = size
        try:
            os.ftruncate(self._fd, self.size)
        except OSError:
            pass          # the file keeps a half line; a reader stops at its last whole one

    def close(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)


class SessionWriter:
    """The lines of a session, from the bytes of both directions (see module docstring).

    ``write`` receives whole lines (``\\n``-ended).  ``stamps`` adds the ``# t=SECONDS >``
    / ``# t=SECONDS <`` line before each line sent / received (``coolmuscle capture``);
    ``wait_decimals`` is the precision of ``@wait`` (6: microseconds)."""

    def __init__(self, write: Callable[[str], object], *, stamps: bool = False,
                 wait_decimals: int = 6) -> None:
        self._write = write
        self.stamps = stamps
        self.wait_decimals = wait_decimals
        self.sent_lines = 0
        self.received_lines = 0
        self.bytes_sent = 0
        self.bytes_received = 0
        self._tx = bytearray()        # a line being sent, not ended yet
        self._tx_time = 0.0           # when its last byte came
        self._tx_cut = False          # its first part went out already (as @send)
        self._tx_text = bytearray()   # the whole line so far (for the echo)
        self._tx_after_cr = False     # the last byte sent was a CR
        self._tx_long = False         # the line being sent went out in pieces (too long)
        self._rx = bytearray()        # received bytes of a line not ended yet
        self._rx_cut = False          # the line being received went out in pieces
        self._rx_time = 0.0           # when its last byte came
        self._rx_after_cr = False     # the last received line ended with a lone CR
        self._sent: list[bytes] = []  # lines sent whose echo has not come
        self._replay_at = 0.0         # where the replay's virtual time stands
        self._last_sent = 0.0

    # -- input --------------------------------------------------------------
    def feed(self, at: float, direction: Direction, data: bytes) -> None:
        """``data`` written to the motor (``">"``) or received (``"<"``) at ``at`` s."""
        if not data:
            return
        if direction == ">":
            self.bytes_sent += len(data)
            self._flush_held_cr()
            self._sent_bytes(at, data)
        else:
            self.bytes_received += len(data)
            self._received_bytes(at, data)

    def tick(self) -> None:
        """Nothing came for a while: a received line ended by a lone CR is complete."""
        self._flush_held_cr()

    def finish(self) -> None:
        """Write what is pending: a line still without its end, either way."""
        self._flush_held_cr()
        if self._rx and (not self._tx or self._rx_time < self._tx_time):
            self._partial_received()                # in the order they came
        if self._tx:
            self._emit_sent(self._tx_time, bytes(self._tx), ended=False)
        if self._rx:
            self._partial_received()

    def _partial_received(self) -> None:
        """Received bytes without their line end (no ``@until``: a ``@wait`` brings the
        replay to when they came)."""
        self._wait_until(self._rx_time)
        self._emit_received(self._rx_time, bytes(self._rx), until=False)
        self._rx.clear()

    # -- lines sent ---------------------------------------------------------
    def _sent_bytes(self, at: float, data: bytes) -> None:
        start = 0
        for end in _SENT_END.finditer(data):
            piece = data[start:end.end()]
            start = end.end()
            if piece == b"\n" and not self._tx and self._tx_after_cr:
                self._emit_sent(at, piece, ended=False)   # the LF of a CRLF: itself
            else:
                self._tx += piece
                self._emit_sent(at, bytes(self._tx), ended=True)
            self._tx_after_cr = piece.endswith(b"\r")
        if start < len(data):
            self._tx += data[start:]
            self._tx_time = at
            self._tx_after_cr = False
            while len(self._tx) >= MAX_PIECE:   # a long line: out in pieces as it comes
                rest = self._tx[MAX_PIECE:]
                self._emit_sent(at, bytes(self._tx[:MAX_PIECE]), ended=False)
                self._tx += rest                 # (_emit_sent emptied it)
                self._tx_text.clear()            # (too long to be an echo worth matching)
                self._tx_long = True

    def _emit_sent(self, at: float, data: bytes, *, ended: bool) -> None:
        """One line sent (``ended``: with its CR or LF) or the part of one so far."""
        self._tx.clear()
        self._wait_until(at)
        lines = [f"# t={at:.6f} >"] if self.stamps else []
        plain = (_plain_line(data[:-1]) if ended and data.endswith(b"\r") and not self._tx_cut
                 else None)
        lines.append(plain if plain is not None else f"@send {escape(data)}")
        self._write("\n".join(lines) + "\n")
        self.sent_lines += 1
        self._last_sent = at
        body = data.rstrip(b"\r\n")
        if ended:
            self._tx_text += body
            if data != b"\n" and not self._tx_long:
                self._sent.append(bytes(self._tx_text))
                del self._sent[:-32]
            self._tx_text.clear()
            self._tx_cut = self._tx_long = False
        else:
            self._tx_text += body
            self._tx_cut = data != b"\n"

    def _wait_until(self, at: float) -> None:
        """``@wait`` to bring the replay to ``at`` (counted as the replay counts it, so
        the rounding of one wait is made up by the next)."""
        pause = round(at - self._replay_at, self.wait_decimals)
        if pause > 0:
            self._write(f"@wait {pause:.{self.wait_decimals}f}\n")
            self._replay_at += pause

    # -- lines received -----------------------------------------------------
    def _received_bytes(self, at: float, data: bytes) -> None:
        if self._rx_after_cr and data[:1] == b"\n" and not self._rx:
            self._sent_part_first()
            self._emit_received(at, b"\n", until=False)      # a CRLF split by a pause
            data = data[1:]
        self._rx_after_cr = False
        if self._rx.endswith(b"\r") and data[:1] != b"\n":
            self._line_received(self._rx_time, bytes(self._rx))   # ended at its CR
            self._rx.clear()
        scan = max(len(self._rx) - 1, 0)     # what was there has no line end (but a CR)
        self._rx += data
        self._rx_time = at
        while True:
            match = _LINE_END.search(self._rx, scan)
            if match is None:
                break
            raw = bytes(self._rx[:match.end()])
            del self._rx[:match.end()]
            scan = 0
            self._line_received(at, raw)
        while len(self._rx) >= MAX_PIECE:
            self._received_piece()

    def _received_piece(self) -> None:
        """The first ``MAX_PIECE`` bytes of a long received line go out as a piece (a CR
        at the end of what came stays: its LF may follow)."""
        cut = min(MAX_PIECE, len(self._rx) - (1 if self._rx.endswith(b"\r") else 0))
        self._sent_part_first()
        self._wait_until(self._rx_time)
        self._emit_received(self._rx_time, bytes(self._rx[:cut]), until=False)
        del self._rx[:cut]
        self._rx_cut = True

    def _flush_held_cr(self) -> None:
        if self._rx.endswith(b"\r"):          # (every other line end has been taken)
            self._line_received(self._rx_time, bytes(self._rx))
            self._rx.clear()
            self._rx_after_cr = True

    def _sent_part_first(self) -> None:
        """A line came while one was being sent: what went out so far goes first (the
        file stays in the order the bytes came)."""
        if self._tx:
            self._emit_sent(self._tx_time, bytes(self._tx), ended=False)

    def _line_received(self, at: float, raw: bytes) -> None:
        self._sent_part_first()
        if self._rx_cut:                 # the last piece of a long line
            self._rx_cut = False
            self._wait_until(at)
            self._emit_received(at, raw, until=False)
            return
        text = raw.rstrip(b"\r\n")
        until = bool(text) and text not in self._sent
        if text in self._sent:
            self._sent.remove(text)
        self._emit_received(at, raw, until=until)

    def _emit_received(self, at: float, raw: bytes, *, until: bool) -> None:
        lines = [f"# t={at:.6f} <"] if self.stamps else []
        if until:
            pattern = until_pattern(raw.rstrip(b"\r\n"))
            lines.append(f"@until {pattern} {2 * (at - self._last_sent) + 2:.1f}")
            self._replay_at = max(self._replay_at, at)
        lines.append(f"<< {escape(raw)}")
        self._write("\n".join(lines) + "\n")
        self.received_lines += 1


class TranscriptRecorder:
    """``coolmuscle term``'s ``:log``: the session to ``path`` as it happens (call
    :meth:`tap` with the bytes; ``@wait`` to the hundredth of a second)."""

    def __init__(self, path: str | os.PathLike[str], source: str = "",
                 on_error: Callable[[str], None] | None = None) -> None:
        self.path = Path(path)
        self._file = LineFile(self.path, on_error)
        self._start = time.monotonic()
        self._file.write("# golden transcript recorded by coolmuscle term"
                         + (f" ({source})" if source else "") + "\n")
        self.writer = SessionWriter(self._file.write, wait_decimals=2)

    def tap(self, direction: str, data: bytes) -> None:
        """Bytes written (``">"``) or received (``"<"``)."""
        self.writer.feed(time.monotonic() - self._start, ">" if direction == ">" else "<",
                         data)

    def close(self) -> None:
        """Write what is pending (a line still without its end) and close the file."""
        self.writer.finish()
        self._file.close()
