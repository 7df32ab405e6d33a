"""Stop signals (SIGINT, SIGTERM, SIGHUP) of the ``coolmuscle`` command: one clean line.

Used by :mod:`.entry` (before anything heavy loads) and :mod:`.cli` (while ``sim``
serves); see docs/reliability.md "signals".
"""

from __future__ import annotations

import signal
from types import FrameType
from typing import Any

#: The signals that stop the program.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class SignalStop(BaseException):
    """Raised by the start-up handler: the program was asked to stop by ``signum``.

    Not a ``KeyboardInterrupt``: the command-line framework would swallow that
    with a message of its own."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_requested: list[int] = []


def _raise_stop(signum: int, _frame: FrameType | None) -> None:
    if not _requested:
        _requested.append(signum)
    raise SignalStop(signum)


def stop_requested() -> int | None:
    """The first stop signal received so far (``None``: none).

    A handler's exception can land where Python ignores it (a weakref callback inside
    the import machinery: "Exception ignored in ..."); the request is kept here, and
    :func:`check_stop` raises it again at the next checkpoint."""
    return _requested[0] if _requested else None


def clear_stop() -> None:
    """The stop request has been acted on (or a new command starts)."""
    _requested.clear()


def check_stop() -> None:
    """Raise :class:`SignalStop` if a stop signal came (a checkpoint of start-up)."""
    if _requested:
        raise SignalStop(_requested[0])


def install_startup_handlers() -> None:
    """Every stop signal raises :class:`SignalStop` (caught by ``cli.main``)."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, _raise_stop)


def serve_until_signal(loop: Any, stop: Any) -> None:
    """While an asyncio loop serves: every stop signal sets the event ``stop`` in it.

    Python-level handlers, not ``loop.add_signal_handler``: taking the loop's handlers
    off again puts the default ones back first (``SIG_DFL``, ``default_int_handler``),
    and a second signal in that instant killed the process with no clean-up or cut the
    clean-up short with a ``KeyboardInterrupt``.  These are replaced in one step by
    :func:`ignore_stop_signals`.  The handler runs in the main thread, between the
    loop's own steps (its ``select`` returns EINTR), and only schedules ``stop.set``."""
    def handler(_signum: int, _frame: FrameType | None) -> None:
        try:
            loop.call_soon_threadsafe(stop.set)
        except RuntimeError:      # the loop is closed: the program is stopping anyway
            pass
    for sig in STOP_SIGNALS:
        signal.signal(sig, handler)


def ignore_stop_signals() -> None:
    """The program is stopping: a second signal must not cut the clean-up short."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


def stop_line(exc: BaseException) -> tuple[str, int]:
    """The one line and exit status for a stop by signal (or Ctrl-C)."""
    signum = exc.signum if isinstance(exc, SignalStop) else signal.SIGINT
    if signum == signal.SIGINT:
        return "coolmuscle: interrupted", 130
    return f"coolmuscle: stopped ({signal.Signals(signum).name})", 128 + signum
