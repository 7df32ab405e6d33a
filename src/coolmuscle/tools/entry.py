"""The ``coolmuscle`` command's entry point: errors as one line, exit codes, a quick start.

``coolmuscle run SCRIPT`` with plain options (:func:`.runcmd.parse_run_args`) runs at
once, without loading the command-line library (typer, rich) or anything the script
does not use (docs/performance.md "Starting a run"); every other command line goes to
the typer application of :mod:`.cli`.  Both paths map errors the same way
(:func:`guarded`): no traceback reaches the user unless ``COOLMUSCLE_DEBUG=1``.

Exit codes: 0 success; 1 a failed run or a runtime error; 2 bad usage or a bad script;
70 an internal error (a bug: please report it).
"""

from __future__ import annotations

import sys

from .exits import guarded


def main(argv: list[str] | None = None) -> None:
    """``coolmuscle ARGS``: a plain ``run`` at once, anything else through :mod:`.cli`."""
    args = sys.argv[1:] if argv is None else list(argv)
    from .runcmd import parse_run_args
    kwargs = parse_run_args(args)
    if kwargs is None:
        from .cli import main as full_main
        full_main(args)
        return

    def quick() -> None:
        from .runcmd import run_command
        code = run_command(**kwargs)
        if code:
            raise SystemExit(code)
    guarded(quick)
