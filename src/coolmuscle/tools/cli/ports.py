"""PORT as every command takes it: a device, HOST:PORT or a pyserial URL.

One parser for every command that talks to a motor (``upload --port``, ``term``,
``capture``, the desk's ``scan``/``backup``/``restore``/``params diff``;
docs/real-motor.md):

* ``/dev/ttyUSB0``, ``COM3``, ``rfc2217://...``: a serial line with a baud rate (a wire);
* ``HOST:PORT``: ``socket://HOST:PORT`` (``coolmuscle sim`` serves 127.0.0.1:5150 and
  prints it so; ``[::1]:5150`` for IPv6);
* any other pyserial URL (``socket://``, ``coolmuscle://``) as it is: no wire, the rate
  of the port means nothing.
"""

from __future__ import annotations

import re

from .usage import UsageError

__all__ = ["port_url", "has_wire"]

_HOST_PORT = re.compile(r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):([0-9]{1,5})")


def port_url(text: str) -> str:
    """The pyserial URL for PORT (``HOST:PORT`` -> ``socket://HOST:PORT``); an empty
    PORT is a :class:`~.usage.UsageError`."""
    text = text.strip()
    if not text:
        raise UsageError("PORT is empty: give a device (/dev/ttyUSB0, COM3), HOST:PORT or a "
                         "pyserial URL")
    if "://" not in text and _HOST_PORT.fullmatch(text):
        return f"socket://{text}"
    return text


def has_wire(url: str) -> bool:
    """Whether ``url`` is a serial line whose baud rate matters (a device, ``rfc2217://``)."""
    return "://" not in url or url.lower().startswith("rfc2217://")
