"""What the TCP servers of the front ends share: their address, the connection limit and
the end of each connection (the CML line ``tcp``, ``modbus-tcp``, EtherNet/IP's 44818).

:class:`StreamServer` admits a connection (at most ``max_clients`` at once; one more
is refused as it arrives: :meth:`StreamServer.refuse`, docs/reliability.md "Bounds"),
hands it to the subclass's :meth:`StreamServer.serve_connection`, and ends it
whatever happened there: a reset or an OS error is one INFO line, anything else is
logged with its traceback and never escapes as a task error, and the socket is
closed.  The subclass owns what it speaks on the connection.
"""

from __future__ import annotations

import asyncio
import logging
from abc import abstractmethod
from typing import Any

from ...errors import TransportError
from .base import Transport, close_stream_server

log = logging.getLogger(__name__)

#: Clients served at once by default; more are refused (docs/reliability.md "Bounds").
DEFAULT_MAX_CLIENTS = 64


class StreamServer(Transport):
    """A transport that is an asyncio TCP server (see the module docstring)."""

    def __init__(self, host: str, port: int, *, max_clients: int = DEFAULT_MAX_CLIENTS) -> None:
        super().__init__()
        self.host = host
        self.requested_port = port
        self.max_clients = max_clients
        self.bound: tuple[str, int] | None = None
        self.refused_clients = 0
        self._server: asyncio.base_events.Server | None = None
        self._writers: set[asyncio.StreamWriter] = set()

    # -- the listening socket ---------------------------------------------------------
    async def listen(self) -> None:
        """Accept on ``host:requested_port`` (port 0: a free one); ``TransportError``
        when it cannot."""
        try:
            self._server = await self.start_server()
        except OSError as exc:
            raise TransportError(f"{self.name}: cannot listen on {self.host}:"
                                 f"{self.requested_port}: {exc.strerror or exc}") from exc
        sockname = self._server.sockets[0].getsockname()
        self.bound = (sockname[0], sockname[1])

    async def start_server(self, port: int | None = None) -> asyncio.base_events.Server:
        """The asyncio server whose connections this class admits (``port``: another
        number than the requested one)."""
        return await asyncio.start_server(self._connection, self.host,
                                          self.requested_port if port is None else port)

    def address(self) -> tuple[str, int]:
        """The address bound (the one asked for before :meth:`listen`)."""
        return self.bound or (self.host, self.requested_port)

    def describe(self) -> str:
        host, port = self.address()
        return f"{self.name}: [{host}]:{port}" if ":" in host else f"{self.name}: {host}:{port}"

    def info(self) -> dict[str, Any]:
        host, port = self.address()
        return {"host": host, "port": port}

    async def close_server(self) -> None:
        """Stop accepting and drop every connection at once."""
        await close_stream_server(self._server, self._writers)
        self._server = None

    # -- one connection ---------------------------------------------------------------
    @property
    def connections(self) -> int:
        """Connections being served now."""
        return len(self._writers)

    def refuse(self, writer: asyncio.StreamWriter) -> None:
        """A client beyond the limit: closed as it arrives (a subclass may say why)."""
        writer.transport.close()

    @abstractmethod
    async def serve_connection(self, reader: asyncio.StreamReader,
                               writer: asyncio.StreamWriter, peer: str) -> None:
        """Serve one admitted connection until it ends (return or raise)."""

    async def _connection(self, reader: asyncio.StreamReader,
                          writer: asyncio.StreamWriter) -> None:
        peer = peer_text(writer.get_extra_info("peername"))
        if len(self._writers) >= self.max_clients:
            self.refused_clients += 1
            log.warning("%s: refused %s: %d clients connected (the limit)", self.name, peer,
                        len(self._writers))
            try:
                self.refuse(writer)
            except (ConnectionError, OSError):
                pass
            return
        self._writers.add(writer)
        try:
            await self.serve_connection(reader, writer, peer)
        except (ConnectionError, OSError) as exc:
            log.info("%s: client %s: %s", self.name, peer, exc)
        except asyncio.CancelledError:
            pass
        except Exception:  # one client's trouble never escapes as a task error
            log.exception("%s: client %s failed", self.name, peer)
        finally:
            self._writers.discard(writer)
            if not writer.transport.is_closing():
                writer.transport.close()


def peer_text(peer: object) -> str:
    """``host:port`` of a peer address (``str`` of anything else)."""
    if isinstance(peer, tuple) and len(peer) >= 2:
        return f"{peer[0]}:{peer[1]}"
    return str(peer)
