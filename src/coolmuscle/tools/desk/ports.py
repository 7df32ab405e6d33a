"""The PORT of the desk commands (docs/real-motor.md): the forms every command takes
(:mod:`coolmuscle.tools.cli.ports`), and opening it."""

from __future__ import annotations

from typing import Any

from ...client.sync import open_port as client_open_port
from ...errors import TransportError
from ..cli.ports import has_wire
from ..cli.ports import port_url as _port_url
from ..cli.usage import UsageError
from .errors import DeskError

__all__ = ["port_url", "has_wire", "open_port"]


def port_url(text: str) -> str:
    """The pyserial URL for PORT, by the one parser every command uses
    (:func:`coolmuscle.tools.cli.ports.port_url`); bad input is a :class:`DeskError`."""
    try:
        return _port_url(text)
    except UsageError as exc:
        raise DeskError(str(exc)) from None


def open_port(url: str, baud: int = 38400) -> Any:
    """Open ``url`` at ``baud``; a port that cannot be opened is a :class:`DeskError`."""
    try:
        return client_open_port(url, baudrate=baud)
    except TransportError as exc:
        raise DeskError(str(exc)) from None
