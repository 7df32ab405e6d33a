"""The ``coolmuscle`` command's first code: signals are handled before anything heavy loads.

``python -m coolmuscle`` and the ``coolmuscle`` script start here, so that a
SIGINT, SIGTERM or SIGHUP at any moment of start-up (while typer, rich and the
model are imported, the store opened, the transports started) ends the program
with one line and the normal clean-up (``finally`` blocks: the store's
transaction rolls back, the pty link is removed), never a traceback or a silent
death.  While ``sim`` serves, its event loop takes the signals over
(:func:`coolmuscle.tools.cli._serve`); once it stops, further signals are
ignored until the process has exited (docs/reliability.md "signals").
"""

from __future__ import annotations

import sys

from .stopsignals import (SignalStop, check_stop, ignore_stop_signals, install_startup_handlers,
                          stop_line)


def main(argv: list[str] | None = None) -> None:
    """Entry point: handlers first, then the command line (:func:`coolmuscle.tools.cli.main`)."""
    install_startup_handlers()
    try:
        from .cli import main as cli_main
        check_stop()
    except (KeyboardInterrupt, SignalStop) as exc:
        ignore_stop_signals()
        text, code = stop_line(exc)
        sys.stderr.write(text + "\n")
        raise SystemExit(code) from None
    cli_main(argv)
