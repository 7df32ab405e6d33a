"""Rate-limited log lines for events a peer can repeat at will (docs/reliability.md
"Log rate limits").

A refused connection, a reset, a connection closed for being idle: each is worth a
line, but a client that repeats it 3,000 times must not write 3,000 lines.  A
:class:`LogLimiter` logs the first ``burst`` events of a window of ``interval``
seconds as they come, counts the rest, and says how many it left out in one summary
line when the window ends (at the next event after it, or on time when given a
``schedule`` such as the event loop's ``call_later``, or at :meth:`LogLimiter.flush`).

The clock is a parameter: the servers run in the wall time of their event loop
(``time.monotonic``, the default); a model-side user would hand in virtual time.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

#: Lines of one kind logged per window, and the window (s), unless told otherwise.
DEFAULT_BURST = 5
DEFAULT_INTERVAL = 10.0

#: ``schedule(delay_s, callback)``: call back once after the delay (``loop.call_later``).
Schedule = Callable[[float, Callable[[], None]], object]


class LogLimiter:
    """At most ``burst`` lines of one kind of event per ``interval`` seconds on
    ``logger`` at ``level``; ``what`` names the events in the summary line
    (``"refused connections"``)."""

    def __init__(self, logger: logging.Logger, level: int, what: str, *,
                 burst: int = DEFAULT_BURST, interval: float = DEFAULT_INTERVAL,
                 clock: Callable[[], float] = time.monotonic,
                 schedule: Schedule | None = None) -> None:
        self.logger = logger
        self.level = level
        self.what = what
        self.burst = burst
        self.interval = interval
        self.clock = clock
        self.schedule = schedule
        self.logged = 0              # lines written, summaries included (tests, reports)
        self.suppressed_total = 0
        self._window: float | None = None
        self._count = 0
        self._suppressed = 0
        self._flush_for: float | None = None     # the window whose summary is scheduled

    def __call__(self, msg: str, *args: object) -> bool:
        """One event: logged (True) or counted for the summary (False)."""
        now = self.clock()
        if self._window is None or now - self._window >= self.interval:
            self.flush()
            self._window, self._count = now, 0
        self._count += 1
        if self._count <= self.burst:
            self._emit(msg, *args)
            return True
        self._suppressed += 1
        self.suppressed_total += 1
        if self.schedule is not None and self._flush_for != self._window:
            self._flush_for = self._window
            self.schedule(max(self._window + self.interval - now, 0.0), self._on_time)
        return False

    def flush(self) -> None:
        """Say now how many events were left out since the last line (if any)."""
        if not self._suppressed:
            return
        count, self._suppressed = self._suppressed, 0
        self._emit("%d more %s in %.0f s (at most %d such lines every %.0f s)",
                   count, self.what, self.interval, self.burst, self.interval)

    def _on_time(self) -> None:
        if self._flush_for is not None and self._flush_for == self._window:
            self.flush()                     # the window ended with no event since
            self._window, self._count = None, 0
        self._flush_for = None

    def _emit(self, msg: str, *args: object) -> None:
        if self.logger.isEnabledFor(self.level):
            self.logger.log(self.level, msg, *args)
            self.logged += 1
