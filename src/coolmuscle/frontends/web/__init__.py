"""The live web dashboard: watch, drive and poke the virtual motors from a browser.

``coolmuscle sim --web [[HOST:]PORT]`` serves it beside the other front doors (default
127.0.0.1:8080); ``coolmuscle run script.cml --web`` plays a script in real time and
shows it.  The page is one more client of the device API (origin ``web``); see
docs/web.md.  The server (aiohttp) is imported only when it is used.
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
