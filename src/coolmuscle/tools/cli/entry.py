"""The ``coolmuscle`` command's first code: stop signals first, then a quick start.

What the command needs for its start is done here, by the program, never by importing
coolmuscle: the stop-signal handlers (the first statement of :func:`main`) and the cache
of the methods :mod:`dataclasses` writes (:mod:`coolmuscle._dataclass_code`, before the
model's modules load).

``python -m coolmuscle`` and the ``coolmuscle`` script start here, so that a SIGINT,
SIGTERM or SIGHUP at any moment of start-up (while the model is imported, the store
opened, the transports started) ends the program with one line and the normal
clean-up (``finally`` blocks: the store's transaction rolls back, the pty link is
removed), never a traceback or a silent death.  While ``sim`` serves, its event loop
takes the signals over (:func:`coolmuscle.tools.cli.app._serve`); once it stops, further
signals are ignored until the process has exited (docs/reliability.md "signals").

``coolmuscle --version`` (or ``version``) answers at once (:mod:`.version`), and
``coolmuscle run SCRIPT`` with plain options (:func:`.runcmd.parse_run_args`) runs at
once, without loading the command-line library (typer, rich) or anything the script
does not use (docs/performance.md "Speed where users feel it"); every other command line goes to
the typer application of :mod:`.cli`.  Both paths map errors the same way
(:func:`.exits.guarded`).

Exit codes: 0 success; 1 a failed run or a runtime error; 2 bad usage or a bad script;
70 an internal error (a bug: please report it); 128 + the signal after a stop signal
(130 for Ctrl-C).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

from .exits import guarded
from .stopsignals import check_stop, install_startup_handlers


def main(argv: list[str] | None = None) -> None:
    """``coolmuscle ARGS``: a plain ``run`` at once, anything else through :mod:`.cli`."""
    install_startup_handlers()
    args = sys.argv[1:] if argv is None else list(argv)
    if args in (["--version"], ["version"]):
        def version() -> None:
            from .version import version_text
            sys.stdout.write(version_text())
        guarded(version)
        return
    from ..._dataclass_code import install as keep_dataclass_code
    keep_dataclass_code()     # this process's classes: their methods not compiled again
    kwargs: dict[str, Any] | None = None
    full_main: Callable[[list[str] | None], None] | None = None

    def parse() -> None:      # imports included: a stop signal may land in any of them
        nonlocal kwargs, full_main
        from .run import parse_run_args
        kwargs = parse_run_args(args)
        if kwargs is None:
            from .app import main as full_main
        check_stop()
    guarded(parse)
    if full_main is not None:
        full_main(argv)       # None: the process's own command line and signal handlers
        return

    def quick() -> None:
        from .run import run_command
        assert kwargs is not None             # parse() gave them: no full_main
        code = run_command(**kwargs)
        check_stop()
        if code:
            raise SystemExit(code)
    guarded(quick)
