"""One-line errors and exit codes of the ``coolmuscle`` command (both its paths:
:mod:`.entry` and the typer application of :mod:`.cli`).

Exit codes: 0 success; 1 a failed run or a runtime error; 2 bad usage or a bad script,
an extra that is not installed or a part this system cannot run (:mod:`coolmuscle.needs`);
70 an internal error (a bug: please report it); 128 + N after stop signal N (130: Ctrl-C).
No traceback reaches the user unless ``COOLMUSCLE_DEBUG=1``.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable

from .stopsignals import Guard, SignalStop, ignore_stop_signals, stop_line, stop_requested

EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_INTERNAL = 70


def guarded(call: Callable[[], object]) -> None:
    """Run ``call``; map what escapes it to one line on stderr and an exit status.

    A stop signal raises :class:`.stopsignals.SignalStop` only inside the ``Guard``,
    which is inside the ``try``: it lands here at any instant of ``call``."""
    try:
        with Guard():
            call()
    except SystemExit:
        raise
    except (KeyboardInterrupt, SignalStop) as exc:   # a stop signal outside a serving loop
        ignore_stop_signals()
        text, code = stop_line(exc)
        _line(text)
        raise SystemExit(code) from None
    except BrokenPipeError:  # `coolmuscle run x.cml | head`: the reader left, not an error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        raise SystemExit(EXIT_FAILED) from None
    except Exception as exc:  # classified here so that the quick path imports nothing more
        stop = _stop_behind(exc)
        if stop is not None:     # a stop signal that Python wrapped (class creation ...)
            ignore_stop_signals()
            text, code = stop_line(stop)
            _line(text)
            raise SystemExit(code) from None
        from ...chain.machine import MachineFileError
        from ...errors import CoolMuscleError
        from ...needs import MissingExtraError, NotOnThisSystemError
        from ..script.runner import ScriptError
        from .usage import UsageError
        if isinstance(exc, (UsageError, ScriptError, MachineFileError, MissingExtraError,
                            NotOnThisSystemError)):
            _report(exc, EXIT_USAGE)
        elif isinstance(exc, (CoolMuscleError, OSError)):
            _report(exc, EXIT_FAILED)
        else:  # a bug: still one line unless asked for more
            _report(exc, EXIT_INTERNAL, prefix="internal error: ")


def _stop_behind(exc: BaseException) -> BaseException | None:
    """The stop signal behind ``exc``: Python turns an exception raised by a signal
    handler in some places into another one (``__set_name__`` during class creation
    gives a ``RuntimeError`` from it); its chain, or the request kept by
    :func:`.stopsignals.stop_requested`, tells."""
    seen: set[int] = set()
    link: BaseException | None = exc
    while link is not None and id(link) not in seen:
        if isinstance(link, (SignalStop, KeyboardInterrupt)):
            return link
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    signum = stop_requested()
    return SignalStop(signum) if signum is not None else None


def _line(text: str) -> None:
    from .run import stderr_line
    stderr_line(text)


def _report(exc: BaseException, code: int, prefix: str = "") -> None:
    if os.environ.get("COOLMUSCLE_DEBUG"):
        import traceback
        traceback.print_exc()
    text = str(exc) or type(exc).__name__
    if prefix:
        text = f"{prefix}{type(exc).__name__}: {text} (COOLMUSCLE_DEBUG=1 shows a traceback)"
    _line(f"coolmuscle: error: {text}")
    raise SystemExit(code) from None
