"""Recording a live session as a golden transcript (docs/scripts.md).

Used by ``:log FILE`` in ``coolmuscle term``.  Every line written to the motor
becomes a script line; every byte received becomes ``<<`` expectations, one per line,
exactly as received (escaped).  A received line that is not an echo is preceded by
``@until ^LINE$ T``: in the replay (``coolmuscle run --check``) virtual time then runs
until the motor says it, as the motor said it after a while here (T is twice that
wait plus 2 s).  Each ``@until`` consumes lines in order, so a report that looks like
an earlier reply (``Ux.1=8``) is matched at its own place.  The pause before each line
sent (since the last line sent or received) is kept as ``@wait``, so the replay asks
its questions at the same moments (wall seconds: record a real-time session, scale 1).
"""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import TextIO

from .runner import escape

__all__ = ["TranscriptRecorder"]


class TranscriptRecorder:
    """Write a session to ``path`` as it happens (call :meth:`tap` with the bytes)."""

    def __init__(self, path: str | Path, source: str = "") -> None:
        self.path = Path(path)
        self._file: TextIO = self.path.open("w", encoding="utf-8")
        self._sent: list[str] = []
        self._rx = bytearray()
        self._tx = bytearray()
        self._last_sent = time.monotonic()
        self._last_activity = self._last_sent
        self._file.write("# golden transcript recorded by coolmuscle term"
                         + (f" ({source})" if source else "") + "\n")
        self._file.flush()

    def tap(self, direction: str, data: bytes) -> None:
        """Bytes written (``">"``) or received (``"<"``)."""
        if direction == ">":
            self._tx += data
            while b"\r" in self._tx:
                line, _, rest = bytes(self._tx).partition(b"\r")
                self._tx[:] = rest
                self._line_sent(line.decode("latin-1"))
        else:
            self._rx += data
            self._lines_received()
        self._file.flush()

    def _line_sent(self, text: str) -> None:
        now = time.monotonic()
        pause = now - self._last_activity
        if pause >= 0.01:
            self._file.write(f"@wait {pause:.2f}\n")
        stripped = text.lstrip()
        if (stripped.startswith(("#", "<< ")) and not stripped[1:2].isdigit()) \
                or re.match(r"@[A-Za-z]", stripped):
            self._file.write(f"@send {escape(text.encode('latin-1'))}\\r\n")  # not a CML line
        else:
            self._file.write(f"{text}\n")
        self._sent.append(text)
        del self._sent[:-32]
        self._last_sent = self._last_activity = now

    def _lines_received(self) -> None:
        while True:
            match = re.search(rb"\r\n|\r(?=[^\n])|\n", bytes(self._rx))
            if match is None:
                return
            raw = bytes(self._rx[:match.end()])
            del self._rx[:match.end()]
            text = raw.rstrip(b"\r\n").decode("latin-1")
            self._last_activity = time.monotonic()
            if text and text not in self._sent:
                waited = time.monotonic() - self._last_sent
                self._file.write(f"@until ^{re.escape(text)}$ {2 * waited + 2:.1f}\n")
            elif text in self._sent:
                self._sent.remove(text)
            self._file.write(f"<< {escape(raw)}\n")

    def close(self) -> None:
        """Write what is pending (a line still without its end) and close the file."""
        if self._rx:
            self._file.write(f"<< {escape(bytes(self._rx))}\n")
            self._rx.clear()
        self._file.close()
