"""``coolmuscle scan``, ``backup``, ``restore`` and ``params diff`` (docs/real-motor.md),
registered on the main command; what they do is :mod:`.actions`.

Exit status: 0 done; 1 a restore that failed part-way (the parts written and not
written are listed) or a diff with differences; 2 bad input, one line: no motor on the
port, a wrong ``--baud``, a backup of another firmware, a value out of range in a backup,
an unreadable file.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import typer

from ..cli.usage import UsageError
from .errors import DeskError

__all__ = ["register", "scan", "backup", "restore", "diff"]

_PORT = ("A serial device (/dev/ttyUSB0, COM3), HOST:PORT (socket://HOST:PORT) or a "
         "pyserial URL.")
_BAUD = ("A K20 rate to try (9600 ... 230400; repeat to try several; default: every "
         "K20 rate, 38400 first).")
_IDS = "Motor IDs to ask, e.g. 1-3,5 (default: ID1, ID2 ... up to the first that is silent)."

params_app = typer.Typer(name="params", no_args_is_help=True, add_completion=False,
                         help="K parameters of real or virtual motors.")


def _say(text: str) -> None:
    from ..cli.run import stderr_line
    stderr_line(text)


def _progress() -> Callable[[str], None] | None:
    """Progress lines on a terminal only."""
    if not sys.stderr.isatty():
        return None
    return lambda text: _say(f"coolmuscle: {text}")


class _Usage:
    """A :class:`DeskError` becomes the command's usage error (exit status 2)."""

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: object) -> None:
        if isinstance(exc, DeskError):
            raise UsageError(str(exc)) from None


def _exit(code: int) -> None:
    if code:
        raise typer.Exit(code)


def scan(
    port: str = typer.Argument(..., metavar="PORT", help=_PORT),
    baud: list[int] | None = typer.Option(None, "--baud", metavar="BPS", help=_BAUD),
    ids: str | None = typer.Option(None, "--ids", metavar="IDS", help=_IDS),
    timeout: float = typer.Option(0.3, "--timeout", metavar="SECONDS", min=0.01, max=10.0,
                                  help="Seconds each motor has to answer a query."),
) -> None:
    """Which motor IDs answer on PORT, at which K20 baud rate, with which firmware.

    Queries only; about 1 s per baud rate and 0.6 s per ID at most (docs/real-motor.md).
    """
    from .actions import do_scan, parse_bauds, parse_ids
    with _Usage():
        _exit(do_scan(port, parse_bauds(baud), parse_ids(ids), timeout, sys.stdout, _say,
                      _progress()))


def backup(
    port: str = typer.Argument(..., metavar="PORT", help=_PORT),
    output: Path = typer.Option(..., "--output", "-o", metavar="FILE.cml",
                                help="The backup file (a coolmuscle run script)."),
    baud: list[int] | None = typer.Option(None, "--baud", metavar="BPS", help=_BAUD),
    ids: str | None = typer.Option(None, "--ids", metavar="IDS", help=_IDS),
    force: bool = typer.Option(False, "--force", help="Replace FILE.cml if it exists."),
) -> None:
    """Read every K parameter, data register and bank of the motors on PORT into a file.

    The file is a script that restore and coolmuscle run play back (docs/real-motor.md).
    """
    from .actions import do_backup, parse_bauds, parse_ids
    with _Usage():
        _exit(do_backup(port, output, parse_bauds(baud), parse_ids(ids), force, _say,
                        _progress()))


def restore(
    file: Path = typer.Argument(..., metavar="FILE.cml", help="A backup (coolmuscle backup)."),
    port: str = typer.Option(..., "--port", metavar="PORT", help=_PORT),
    save: bool = typer.Option(False, "--save",
                              help="Send $ to each motor at the end (2.1.2)."),
    baud: list[int] | None = typer.Option(None, "--baud", metavar="BPS", help=_BAUD),
) -> None:
    """Write a backup to the motors on PORT, part by part, each read back."""
    from .actions import do_restore, parse_bauds
    with _Usage():
        _exit(do_restore(file, port, parse_bauds(baud), save, sys.stdout, _say, _progress()))


@params_app.command("diff")
def diff(
    a: str = typer.Argument(..., metavar="A", help="A backup file, 'factory[:cm2|rt3|cm1]' "
                                                   "or a PORT (read live)."),
    b: str = typer.Argument(..., metavar="B", help="The same, the other side."),
    everything: bool = typer.Option(False, "--all",
                                    help="Also the data registers and the banks."),
    baud: list[int] | None = typer.Option(None, "--baud", metavar="BPS", help=_BAUD),
) -> None:
    """The K parameters that differ between A and B, each with its meaning (table 6.1).

    Exit status 1 when they differ, as diff(1) (docs/real-motor.md).
    """
    from .actions import do_diff, parse_bauds
    with _Usage():
        _exit(do_diff(a, b, everything, parse_bauds(baud), sys.stdout, _progress()))


def register(app: typer.Typer) -> None:
    """Add ``scan``, ``backup``, ``restore`` and ``params diff`` to ``coolmuscle``."""
    app.command()(scan)
    app.command()(backup)
    app.command()(restore)
    app.add_typer(params_app, name="params")
