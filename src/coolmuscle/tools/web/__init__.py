"""The live web dashboard: watch, drive and poke the virtual motors from a browser.

``coolmuscle sim --web [[HOST:]PORT]`` serves it beside the other front doors (default
127.0.0.1:8080); ``coolmuscle run script.cml --web`` plays a script in real time and
shows it (:mod:`.run`); ``coolmuscle web PORT_OR_URL [--twin [MACHINE.toml]]`` serves
the same page in front of a real motor (:mod:`.command`, :mod:`.line`, :mod:`.linepage`,
with a live virtual twin, :mod:`.twin`; docs/real-motor.md).  The desk of the page (the
K editor, the motor buttons, scan, backup, restore) is :mod:`.deskpage` over the client
operations of :mod:`.pageops`, for virtual and real motors alike.  The page is one
more client of the device API (origin ``web``); its banks and traces use the host
tools (the checker, the client's bank upload with read-back, the trace recorder and its
plot), which is why it is a tool and not a front end (docs/architecture.md,
docs/web.md).  The server (aiohttp) is imported only when it is used.
"""

from __future__ import annotations

from typing import Any

from .access import DEFAULT_HOST, DEFAULT_PORT, parse_web_address

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "WebTransport", "parse_web_address"]


def __getattr__(name: str) -> Any:
    if name == "WebTransport":
        from .server import WebTransport
        return WebTransport
    raise AttributeError(name)
