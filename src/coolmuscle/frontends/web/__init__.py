"""The live web dashboard: watch, drive and poke the virtual motors from a browser.

``coolmuscle sim --web [[HOST:]PORT]`` serves it beside the other front doors (default
127.0.0.1:8080); ``coolmuscle run script.cml --web`` plays a script in real time and
shows it.  The page is one more client of the device API (origin ``web``); see
docs/web.md.  The server needs aiohttp (a runtime dependency of coolmuscle).
"""

from __future__ import annotations

from .access import DEFAULT_HOST, DEFAULT_PORT, parse_web_address
from .server import WebTransport

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "WebTransport", "parse_web_address"]
