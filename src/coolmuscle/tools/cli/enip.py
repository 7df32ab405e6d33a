"""Command-line glue: ``coolmuscle sim --firmware cm1 --enip [HOST[:PORT]]`` and
``coolmuscle enip eds``.

``--enip`` takes an optional value: alone it means 127.0.0.1 (port 44818);
:func:`optional_value_argv` inserts that default before Typer parses the line.  The
module is :mod:`coolmuscle.frontends.enip` (docs/enip.md).
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import typer

from ...errors import TransportError

if TYPE_CHECKING:
    from ...frontends.transports.base import Transport

DEFAULT_HOST = "127.0.0.1"
FLAG = "--enip"

enip_app = typer.Typer(name="enip", no_args_is_help=True, add_completion=False,
                       help="The CM1 EtherNet/IP interface module (docs/enip.md).")


@enip_app.command("eds")
def eds_command() -> None:
    """Print the module's EDS file (for RSLogix / the scanner's tool)."""
    from ...frontends.enip.cm1.eds import generate
    sys.stdout.write(generate())


def register(app: typer.Typer) -> None:
    """Add the ``enip`` command group to the main application."""
    app.add_typer(enip_app, name="enip")


def optional_value_argv(argv: list[str] | None) -> list[str] | None:
    """``--enip`` with no value (last, or before another option) gets 127.0.0.1."""
    args = list(sys.argv[1:] if argv is None else argv)
    if FLAG not in args:
        return argv
    out: list[str] = []
    for i, arg in enumerate(args):
        out.append(arg)
        if arg == FLAG and (i + 1 == len(args) or args[i + 1].startswith("-")):
            out.append(DEFAULT_HOST)
    return out


def parse_enip(value: str) -> tuple[str, int]:
    """``HOST``, ``HOST:PORT`` or ``PORT`` -> (host, port); port 0 picks a free one."""
    from ...frontends.enip.server import DEFAULT_PORT
    host, sep, port_text = value.rpartition(":")
    if not sep:
        if value.isdigit():
            host, port_text = DEFAULT_HOST, value
        else:
            host, port_text = value, str(DEFAULT_PORT)
    try:
        port = int(port_text)
    except ValueError:
        raise TransportError(f"--enip: bad port {port_text!r} (HOST, HOST:PORT or PORT)") from None
    if not 0 <= port <= 65535:
        raise TransportError(f"--enip: port {port} out of range 0..65535")
    return (host or DEFAULT_HOST).strip("[]"), port


def transports(value: str | None, io_port: int, firmware: str,
               priority: int | None = None) -> list[Transport]:
    """The EtherNet/IP transport for ``--enip`` (the CM1 module only)."""
    if value is None:
        return []
    if firmware != "cm1":
        raise TransportError("--enip is the CM1 EtherNet/IP module: use --firmware cm1")
    from ...frontends.enip.server import EnipTransport
    host, port = parse_enip(value)
    return [EnipTransport(host=host, port=port, io_port=io_port, priority=priority)]
