"""Stop signals (SIGINT, SIGTERM, SIGHUP) of the ``coolmuscle`` command: one clean line.

From the instant :func:`install_startup_handlers` runs (the first code of the command:
:func:`coolmuscle.tools.cli.entry.main`, and ``python -m coolmuscle`` before it loads
the entry module) every stop signal ends the
program with one line and ``128 + N`` (130 for Ctrl-C), whatever is running:

* inside :func:`.exits.guarded` (a :class:`Guard`), where the command's work and
  everything it opens (the store, the pty link) lives, the handler raises
  :class:`SignalStop`; ``guarded`` runs the clean-up (``finally`` blocks) and prints
  the line;
* outside it (the package and its first modules loading, runpy's machinery, the
  instants between two guarded calls, the interpreter's exit) nothing is open that
  needs cleaning up, and an exception raised there is a traceback (nothing catches
  it): the handler prints the line and ends the process at once (:func:`_stop_now`);
* where Python swallows a handler's exception (a weakref callback, ``__del__``, an
  atexit hook: "Exception ignored in ...") it is kept quiet (:func:`_quiet_unraisable`);
  the request is kept and :func:`check_stop` raises it again at the next checkpoint;
* while ``sim`` serves, :func:`run_served` replaces the handlers before its event loop
  runs its first callback (asyncio logs a ``BaseException`` raised in a callback as
  "Exception in callback" with a traceback); a signal then stops the loop.

Before the handlers are installed (the interpreter's own start-up) Python's default
applies.  See docs/reliability.md "signals".
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable, Coroutine
from types import FrameType, TracebackType
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    import asyncio

T = TypeVar("T")

#: The signals that stop the program: those of them this system has (Windows has no
#: SIGHUP; its Ctrl-Break is SIGBREAK).
STOP_SIGNALS = tuple(getattr(signal, name)
                     for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGBREAK")
                     if hasattr(signal, name))


class SignalStop(BaseException):
    """Raised by the start-up handler: the program was asked to stop by ``signum``.

    Not a ``KeyboardInterrupt``: the command-line framework would swallow that
    with a message of its own."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_requested: list[int] = []
#: How many :class:`Guard` blocks the main thread is in (:func:`.exits.guarded`).
_depth = [0]


class Guard:
    """``with Guard():`` - a stop signal raises :class:`SignalStop` here (the caller
    catches it and cleans up); outside every guard it ends the process at once."""

    def __enter__(self) -> None:
        _depth[0] += 1

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 tb: TracebackType | None) -> None:
        _depth[0] -= 1


def _raise_stop(signum: int, _frame: FrameType | None) -> None:
    if not _requested:
        _requested.append(signum)
    if _depth[0] > 0:
        raise SignalStop(signum)
    _stop_now(signum)


def _stop_now(signum: int, _exit: Callable[[int], Any] = os._exit,
              _write: Callable[[int, bytes], int] = os.write) -> None:
    """Outside every guard: the stop line, then the end of the process (no clean-up is
    due there; what ``print`` buffered for stdout is written first)."""
    ignore_stop_signals()
    text, code = stop_line(SignalStop(signum))
    try:
        if sys.stdout is not None:
            sys.stdout.flush()
    except Exception:         # a reader gone, or the stream busy in the interrupted code
        pass
    try:
        _write(2, (text + "\n").encode())
    except OSError:
        pass
    _exit(code)


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
    """Every stop signal raises :class:`SignalStop` inside a :class:`Guard` (caught by
    ``exits.guarded``) and ends the process with its line outside one."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, _raise_stop)
    if sys.unraisablehook is not _quiet_unraisable:
        global _next_unraisable_hook
        _next_unraisable_hook = sys.unraisablehook
        sys.unraisablehook = _quiet_unraisable


_next_unraisable_hook: Callable[[Any], object] = sys.__unraisablehook__


def _quiet_unraisable(unraisable: Any) -> None:
    """A :class:`SignalStop` Python could not raise (it landed in a weakref callback,
    ``__del__``, an atexit hook) prints nothing: the request is kept for
    :func:`check_stop`.  Anything else goes to the hook that was there before."""
    if isinstance(unraisable.exc_value, SignalStop):
        return
    _next_unraisable_hook(unraisable)


def serve_until_signal(loop: Any, stop: Any) -> None:
    """While an asyncio loop serves: every stop signal sets the event ``stop`` in it.

    Python-level handlers, not ``loop.add_signal_handler``: taking the loop's handlers
    off again puts the default ones back first (``SIG_DFL``, ``default_int_handler``),
    and a second signal in that instant killed the process with no clean-up or cut the
    clean-up short with a ``KeyboardInterrupt``.  These are replaced in one step by
    :func:`ignore_stop_signals`.  The handler runs in the main thread, between the
    loop's own steps (its ``select`` returns EINTR), keeps the request
    (:func:`stop_requested`) and schedules ``stop.set``; the loop need not run yet."""
    def handler(signum: int, _frame: FrameType | None) -> None:
        if not _requested:
            _requested.append(signum)
        try:
            loop.call_soon_threadsafe(stop.set)
        except RuntimeError:      # the loop is closed: the program is stopping anyway
            pass
    for sig in STOP_SIGNALS:
        signal.signal(sig, handler)


def run_served(main: Callable[[asyncio.Event], Coroutine[Any, Any, T]]) -> T:
    """Run ``main(stop)`` in a new event loop whose stop signals set ``stop``.

    The handlers of :func:`serve_until_signal` are in place before the loop runs its
    first callback, so no stop signal raises inside the loop's machinery.  ``main``
    may call :func:`check_stop` (a signal before it served anything: one line and
    128 + N); when it returns, the stop it served is done with (the request is
    cleared) and further signals are ignored until the process ends."""
    import asyncio

    with asyncio.Runner() as runner:
        stop = asyncio.Event()
        serve_until_signal(runner.get_loop(), stop)
        try:
            result = runner.run(main(stop))
        finally:
            ignore_stop_signals()          # a second signal must not cut the clean-up short
    clear_stop()
    return result


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
