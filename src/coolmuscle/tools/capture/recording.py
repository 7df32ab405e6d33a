"""The capture file: a header, the session as a script, an end line.

The format is agreed with ``coolmuscle compare`` and ``fit`` (docs/user-guide.md
"coolmuscle capture"): line 1 ``# coolmuscle capture: port=... baud=... parity=...
echo=... started=...`` (then ``k20=``, ``k23=`` when the probe read them, ``motors=``
when given), ``# chain: ...`` when the chain is known, the session as
:class:`~coolmuscle.tools.script.transcript.SessionWriter` writes it with ``# t=`` stamps
(seconds since the capture started, monotonic clock, 6 decimals), and, when the capture
ends cleanly, ``# end: sent=N received=N bytes_to_motor=N bytes_from_motor=N
stopped=WHY``.

:class:`CaptureFile` takes the relay's bytes with the instant they were seen
(:meth:`CaptureFile.put`, cheap, any thread) and writes them on a thread of its own, so
a slow or full disk never holds the relay up; the file is written as it goes, whole
lines at a time, a long line in pieces (:class:`SessionWriter`).  At most
``MAX_QUEUED`` bytes wait to be written: beyond that :meth:`CaptureFile.put` waits until
the writer has caught up (the relay then stops reading that side: back pressure), unless
the capture is ending (:meth:`CaptureFile.stop_waiting`), so what waits is written within
a fraction of a second when it ends.
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

from ..script.transcript import Direction, LineFile, SessionWriter
from .settings import LineSettings

__all__ = ["CaptureFile", "header_lines"]

#: The writer wakes this often (s) and writes what came meanwhile: waking for every
#: chunk would compete with the relay's threads for the processor and the interpreter
#: just when they pass bytes on.  A round with nothing new ends a line held at a lone CR.
ROUND = 0.02
#: Bytes, and line ends, waiting to be written at most before :meth:`CaptureFile.put`
#: waits.  The writer takes about 60 ms a MiB of long lines and 20 µs a line, so what
#: waits is written within about 0.4 s when the capture ends.
MAX_QUEUED = 1 << 20
MAX_QUEUED_LINES = 16_384
#: Longest single wait of ``put`` before it looks again (s).
PUT_POLL = 0.1


def _word(value: str) -> str:
    """A header value without spaces (the header is ``key=value`` words)."""
    return value.replace("%", "%25").replace(" ", "%20")


def header_lines(url: str, settings: LineSettings, started: datetime, *,
                 motors: int | None = None, machine: str | None = None) -> list[str]:
    """Line 1 and, when the chain is known, the ``# chain:`` line."""
    words = [f"port={_word(url)}", f"baud={settings.baud}", f"parity={settings.parity}",
             f"echo={settings.echo_word()}",
             "started=" + started.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")]
    if settings.k20 is not None:
        words.append(f"k20={settings.k20}")
    if settings.k23 is not None:
        words.append(f"k23={settings.k23}")
    if motors is not None:
        words.append(f"motors={motors}")
    lines = ["# coolmuscle capture: " + " ".join(words)]
    chain = []
    if motors is not None:
        chain.append(f"motors={motors}")
    if settings.firmware is not None:
        chain.append(f"firmware={settings.firmware}")
    if machine is not None:
        chain.append(f"machine={_word(machine)}")
    if chain:
        lines.append("# chain: " + " ".join(chain))
    return lines


class CaptureFile:
    """Writes a capture to ``path`` (created now; see module docstring).

    ``on_error`` hears, once, that the file stopped growing (a full disk): the relay
    goes on and the file keeps what was written, up to its last whole line."""

    def __init__(self, path: str | os.PathLike[str],
                 header: Callable[[datetime], list[str]],
                 on_error: Callable[[str], None]) -> None:
        self.path = Path(path)
        self.on_error = on_error
        self.file = LineFile(self.path, on_error)
        self.start_ns = time.monotonic_ns()             # t=0 of the stamps ...
        started = datetime.now(UTC)            # ... and started= of the header
        self.file.write("".join(line + "\n" for line in header(started)))
        self.writer = SessionWriter(self.file.write, stamps=True)
        self._failed = False
        self._items: deque[tuple[int, Direction, bytes, int]] = deque()
        self._queued = 0                 # bytes in _items
        self._lines = 0                  # line ends in _items
        self._lock = threading.Lock()
        self._room = threading.Condition(self._lock)
        self._closing = threading.Event()
        self._ending = threading.Event()
        self.peak_queued = 0
        self._thread = threading.Thread(target=self._run, name="capture-writer", daemon=True)
        self._thread.start()

    def put(self, direction: Direction, data: bytes) -> None:
        """``data`` seen now going to the motor (``">"``) or coming from it (``"<"``);
        waits while ``MAX_QUEUED`` bytes wait to be written (not once the capture ends)."""
        lines = data.count(b"\n") + data.count(b"\r")
        with self._room:
            while (self._queued >= MAX_QUEUED or self._lines >= MAX_QUEUED_LINES) \
                    and not self._ending.is_set():
                self._room.wait(PUT_POLL)
            self._items.append((time.monotonic_ns(), direction, data, lines))  # in order
            self._queued += len(data)
            self._lines += lines
            self.peak_queued = max(self.peak_queued, self._queued)
            if self._half_full():
                self._room.notify_all()          # the writer starts at once

    def stop_waiting(self) -> None:
        """The capture ends: :meth:`put` takes what comes without waiting from now on."""
        self._ending.set()
        with self._room:
            self._room.notify_all()

    def _take(self) -> tuple[int, Direction, bytes] | None:
        with self._room:
            if not self._items:
                return None
            at, direction, data, lines = self._items.popleft()
            self._queued -= len(data)
            self._lines -= lines
            self._room.notify_all()
            return at, direction, data

    def _half_full(self) -> bool:
        return self._queued >= MAX_QUEUED // 2 or self._lines >= MAX_QUEUED_LINES // 2

    def _run(self) -> None:
        while True:
            with self._room:       # a round, or at once when half full or closing
                self._room.wait_for(lambda: self._closing.is_set() or self._half_full(),
                                    timeout=ROUND)
            closing = self._closing.is_set()
            if not self._items:
                if closing:
                    return
                self.writer.tick()
            while (item := self._take()) is not None:
                at, direction, data = item
                if self._failed:
                    continue
                try:
                    self.writer.feed((at - self.start_ns) / 1e9, direction, data)
                except Exception as exc:  # a bug here must not stop the relay: said once
                    self._failed = True
                    self.on_error(f"{self.path} stopped growing: internal error "
                                  f"{type(exc).__name__}: {exc}")

    def close(self, stopped: str | None) -> None:
        """Write what is queued and pending; the end line when ``stopped`` says why."""
        self.stop_waiting()
        self._closing.set()
        with self._room:
            self._room.notify_all()
        self._thread.join()
        if self._failed:
            self.file.close()
            return
        self.writer.finish()
        w = self.writer
        if stopped is not None:
            self.file.write(f"# end: sent={w.sent_lines} received={w.received_lines} "
                            f"bytes_to_motor={w.bytes_sent} bytes_from_motor={w.bytes_received}"
                            f" stopped={stopped}\n")
        self.file.close()
