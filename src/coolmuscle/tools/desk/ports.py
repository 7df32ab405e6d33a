"""The PORT of the desk commands: a pyserial URL, a device, or HOST:PORT (docs/real-motor.md).

* ``/dev/ttyUSB0``, ``COM3``, ``rfc2217://...``: a serial line with a baud rate (a wire);
* ``HOST:PORT``: ``socket://HOST:PORT`` (``coolmuscle sim`` serves 127.0.0.1:5150);
* any other pyserial URL (``socket://``, ``coolmuscle://``) as it is: no wire, the rate
  of the port means nothing.
"""

from __future__ import annotations

import re
from typing import Any

from ...client.sync import open_port as client_open_port
from ...errors import TransportError
from .errors import DeskError

__all__ = ["port_url", "has_wire", "open_port"]

_HOST_PORT = re.compile(r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):([0-9]{1,5})")


def port_url(text: str) -> str:
    """The pyserial URL for PORT as the commands take it (``HOST:PORT`` -> ``socket://``)."""
    text = text.strip()
    if not text:
        raise DeskError("PORT is empty: give a device (/dev/ttyUSB0, COM3), HOST:PORT or a "
                        "pyserial URL")
    if "://" not in text and _HOST_PORT.fullmatch(text):
        return f"socket://{text}"
    return text


def has_wire(url: str) -> bool:
    """Whether ``url`` is a serial line whose baud rate matters (a device, ``rfc2217://``)."""
    return "://" not in url or url.lower().startswith("rfc2217://")


def open_port(url: str, baud: int = 38400) -> Any:
    """Open ``url`` at ``baud``; a port that cannot be opened is a :class:`DeskError`."""
    try:
        return client_open_port(url, baudrate=baud)
    except TransportError as exc:
        raise DeskError(str(exc)) from None
