"""Who may use the dashboard: bind address, the access token, Host and Origin checks.

Anything that moves a motor must not be open to the network by default (project
rule "safe defaults"): the dashboard binds 127.0.0.1 unless told otherwise.  When it
is bound to any other address, every request but the page itself needs the token
printed at start.  On loopback a browser page from another site must not drive the
motors either (cross-site WebSocket, DNS rebinding), so the ``Host`` header must name
a loopback host and a WebSocket's ``Origin`` must be the page's own.  Nor may it make
the simulator prepare downloads (a cross-site ``<img src=".../api/plot.png">`` would
pause the motors' time for each plot): a request for a download whose ``Origin`` is not
the page's own, or whose ``Sec-Fetch-Site`` (Fetch Metadata, sent by every current
browser) is other than ``same-origin`` or ``none`` (typed in, a bookmark), is refused
(:meth:`Access.fetch_ok`).  A client that sends neither (a script, curl) is not a
browser page and is let in, as for the WebSocket.
"""

from __future__ import annotations

import hmac
import ipaddress
import os
import re
import secrets
from urllib.parse import urlsplit

from ...errors import TransportError

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8080

_ADDRESS = re.compile(r"^(?:(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]*):)?(?P<port>\d+)$")
_LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1", "[::1]"})


def parse_web_address(text: str | None) -> tuple[str, int]:
    """``None``/``""`` -> 127.0.0.1:8080; ``"9000"``; ``"0.0.0.0:8080"``; ``"[::1]:8080"``;
    a host alone (``"0.0.0.0"``) takes port 8080."""
    if text is None or not text.strip():
        return DEFAULT_HOST, DEFAULT_PORT
    if _is_ip(text.strip()) or text.strip().lower() == "localhost":   # a host alone
        return text.strip().strip("[]"), DEFAULT_PORT
    match = _ADDRESS.match(text.strip())
    if match is None:
        raise TransportError(f"bad web address {text!r}: expected [HOST:]PORT, "
                             "e.g. 8080 or 0.0.0.0:8080")
    port = int(match.group("port"))
    if not 0 <= port <= 65535:
        raise TransportError(f"bad web port {port} (0..65535)")
    host = (match.group("host") or DEFAULT_HOST).strip("[]") or DEFAULT_HOST
    return host, port


def _is_ip(text: str) -> bool:
    try:
        ipaddress.ip_address(text.strip("[]"))
    except ValueError:
        return False
    return not text.isdigit()


def looks_like_address(text: str) -> bool:
    """Whether a command-line word is a ``[HOST:]PORT`` (else it is the next argument)."""
    return bool(_ADDRESS.match(text.strip()))


DEFAULT_ADDRESS = f"{DEFAULT_HOST}:{DEFAULT_PORT}"


def expand_web_flag(argv: list[str]) -> list[str]:
    """Give a bare ``--web`` (last, or before an option or a script) its default address.

    The word after ``--web`` is its value unless it is an option, a ``.cml`` script or
    a file that exists (``run --web script.cml``), so a malformed address is reported
    as one."""
    out: list[str] = []
    for i, word in enumerate(argv):
        out.append(word)
        if word == "--web":
            following = argv[i + 1] if i + 1 < len(argv) else None
            if following is None or not _web_value(following):
                out.append(DEFAULT_ADDRESS)
    return out


def _web_value(word: str) -> bool:
    if looks_like_address(word):
        return True
    return not (word.startswith("-") or word.lower().endswith(".cml") or os.path.exists(word))


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    if host.lower() in _LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class Access:
    """The access rules of one dashboard server (see the module docstring)."""

    def __init__(self, host: str, token: str | None = None) -> None:
        self.loopback = is_loopback(host)
        self.token = None if self.loopback else (token or secrets.token_urlsafe(16))

    @property
    def token_required(self) -> bool:
        return self.token is not None

    def token_ok(self, given: str | None) -> bool:
        """The token check (constant time); always true on loopback."""
        if self.token is None:
            return True
        if given is None:
            return False
        # surrogates (undecodable header bytes) or any odd text: compared as bytes, never
        # raising ("surrogateescape" keeps every byte it was given)
        return hmac.compare_digest(given.encode("utf-8", "surrogateescape"),
                                   self.token.encode())

    def host_ok(self, host_header: str | None) -> bool:
        """On loopback the ``Host`` header must name a loopback host (DNS rebinding)."""
        if not self.loopback:
            return True
        if not host_header:
            return False
        return is_loopback(_host_of(host_header))

    def origin_ok(self, origin: str | None, host_header: str | None) -> bool:
        """A browser's ``Origin`` must be the page's own scheme-less ``host:port``."""
        if origin is None:          # not a browser (a script, a test client)
            return True
        try:
            netloc = urlsplit(origin).netloc.lower()
        except ValueError:          # "http://[::1" and other unparsable origins: refused
            return False
        return bool(host_header) and netloc == str(host_header).lower()


    def fetch_ok(self, origin: str | None, fetch_site: str | None,
                 host_header: str | None) -> bool:
        """A download asked by the page itself (or by no browser), never by another
        site's page: ``Origin`` as :meth:`origin_ok`, ``Sec-Fetch-Site`` ``same-origin``
        or ``none`` when given."""
        if fetch_site is not None and fetch_site.strip().lower() not in SAME_SITE_FETCHES:
            return False
        return self.origin_ok(origin, host_header)


#: ``Sec-Fetch-Site`` values of a request the page itself made, or the user (typed in,
#: a bookmark); ``same-site`` is another port or scheme of the host: another site here.
SAME_SITE_FETCHES = frozenset({"same-origin", "none"})


def _host_of(host_header: str) -> str:
    """``127.0.0.1:8080`` -> ``127.0.0.1``; ``[::1]:8080`` -> ``::1``."""
    text = host_header.strip()
    if text.startswith("["):
        return text[1:text.find("]")] if "]" in text else text
    return text.rsplit(":", 1)[0] if text.count(":") == 1 else text
