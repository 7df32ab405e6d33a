"""What the TCP servers of the front ends share: their address, the connection limit,
the idle policy and the end of each connection (the CML line ``tcp``, ``modbus-tcp``,
EtherNet/IP's 44818).

:class:`StreamServer` admits a connection (at most ``max_clients`` at once),
hands it to the subclass's :meth:`StreamServer.serve_connection`, and ends it
whatever happened there: a reset or an OS error is one INFO line, anything else is
logged with its traceback and never escapes as a task error, and the socket is
closed.  The subclass owns what it speaks on the connection.

**Idle policy** (docs/reliability.md "Connections"; ``idle_timeout`` set): the
subclass says when a connection sent a complete request (:meth:`StreamServer.request_seen`:
a CML line, a Modbus ADU, an EtherNet/IP session).  When every place is taken, a new
client is admitted by closing the connection idle longest among those that never sent
a complete request or sent none for ``idle_timeout`` seconds
(:meth:`StreamServer.evict` may say why first); only when every connection is in use
is the newcomer refused (:meth:`StreamServer.refuse`).  So connections that never
speak cannot lock polite clients out.  Nothing is closed while there is room.  This is
the rule the Modbus Messaging on TCP/IP Implementation Guide V1.0b gives a server at
its connection limit (4.2.1, connection management: close the connection unused
longest to accept a new one); pymodbus's own server has neither limit nor policy.
Without ``idle_timeout`` (``None``) a server beyond its limit refuses, as before.

Refusals, evictions and resets are logged through a :class:`~.lograte.LogLimiter`
each: a client that repeats them at will writes a few lines and a summary, not one
line per event.  :meth:`StreamServer.send` writes only to a connection that is still
open (a peer that reset gets no more replies, and asyncio no warning per write).
"""

from __future__ import annotations

import asyncio
import logging
from abc import abstractmethod
from typing import Any

from ...errors import TransportError
from .base import Transport, close_stream_server
from .lograte import LogLimiter

log = logging.getLogger(__name__)

#: Clients served at once by default; more are refused (docs/reliability.md "Bounds").
DEFAULT_MAX_CLIENTS = 64
#: Seconds without a complete request after which a connection may be closed to admit
#: a new client while every place is taken (the text line and Modbus TCP).
DEFAULT_IDLE_TIMEOUT = 60.0


class _Slot:
    """One admitted connection: when it came and when it last sent a whole request."""

    __slots__ = ("accepted", "last_request", "peer")

    def __init__(self, peer: str, now: float) -> None:
        self.peer = peer
        self.accepted = now
        self.last_request: float | None = None

    def idle_since(self) -> float:
        return self.accepted if self.last_request is None else self.last_request


class StreamServer(Transport):
    """A transport that is an asyncio TCP server (see the module docstring)."""

    def __init__(self, host: str, port: int, *, max_clients: int = DEFAULT_MAX_CLIENTS,
                 idle_timeout: float | None = None) -> None:
        super().__init__()
        self.host = host
        self.requested_port = port
        self.max_clients = max_clients
        self.idle_timeout = idle_timeout
        self.bound: tuple[str, int] | None = None
        self.refused_clients = 0
        self.evicted_clients = 0
        self._server: asyncio.base_events.Server | None = None
        self._writers: dict[asyncio.StreamWriter, _Slot] = {}
        self._log_refused = self._limiter(logging.WARNING, "refused connections")
        self._log_evicted = self._limiter(logging.INFO, "idle connections closed")
        self._log_ended = self._limiter(logging.INFO, "connections ended by the client")

    def _limiter(self, level: int, what: str) -> LogLimiter:
        return LogLimiter(log, level, what, schedule=_call_later)

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
        for limiter in (self._log_refused, self._log_evicted, self._log_ended):
            limiter.flush()

    # -- one connection ---------------------------------------------------------------
    @property
    def connections(self) -> int:
        """Connections being served now."""
        return len(self._writers)

    @property
    def silent_connections(self) -> int:
        """Connections that have not sent a complete request yet."""
        return sum(1 for slot in self._writers.values() if slot.last_request is None)

    def request_seen(self, writer: asyncio.StreamWriter) -> None:
        """The connection of ``writer`` sent a complete request now (the idle policy)."""
        slot = self._writers.get(writer)
        if slot is not None:
            slot.last_request = _now()

    def send(self, writer: asyncio.StreamWriter, data: bytes) -> bool:
        """Write ``data`` unless the connection is closing (the peer reset or left);
        ``False`` then: stop answering it."""
        if writer.transport.is_closing():
            return False
        writer.write(data)
        return True

    def refuse(self, writer: asyncio.StreamWriter) -> None:
        """A client beyond the limit: closed as it arrives (a subclass may say why)."""
        writer.transport.close()

    def evict(self, writer: asyncio.StreamWriter, idle: float) -> None:
        """An idle connection closed to admit a new client (a subclass may say why):
        closed (FIN), or reset when output it did not read is still waiting."""
        if writer.transport.get_write_buffer_size():
            writer.transport.abort()
        else:
            writer.transport.close()

    @abstractmethod
    async def serve_connection(self, reader: asyncio.StreamReader,
                               writer: asyncio.StreamWriter, peer: str) -> None:
        """Serve one admitted connection until it ends (return or raise)."""

    def _make_room(self) -> bool:
        """Room for one more: there is, or the idle policy closed a connection for it."""
        if len(self._writers) < self.max_clients:
            return True
        if self.idle_timeout is None:
            return False
        now = _now()
        idle = [(slot.idle_since(), writer) for writer, slot in self._writers.items()
                if slot.last_request is None or now - slot.last_request >= self.idle_timeout]
        if not idle:
            return False
        since, writer = min(idle, key=lambda pair: pair[0])
        slot = self._writers.pop(writer)
        self.evicted_clients += 1
        self._log_evicted("%s: closed %s (%s for %.1f s) to admit a new client: %d "
                          "clients connected (the limit)", self.name, slot.peer,
                          "silent" if slot.last_request is None else "idle", now - since,
                          self.max_clients)
        try:
            self.evict(writer, now - since)
        except (ConnectionError, OSError):
            writer.transport.abort()
        return True

    async def _connection(self, reader: asyncio.StreamReader,
                          writer: asyncio.StreamWriter) -> None:
        peer = peer_text(writer.get_extra_info("peername"))
        if not self._make_room():
            self.refused_clients += 1
            self._log_refused("%s: refused %s: %d clients connected (the limit), each "
                              "in use", self.name, peer, len(self._writers))
            try:
                self.refuse(writer)
            except (ConnectionError, OSError):
                pass
            return
        self._writers[writer] = _Slot(peer, _now())
        try:
            await self.serve_connection(reader, writer, peer)
        except (ConnectionError, OSError) as exc:
            self._log_ended("%s: client %s: %s", self.name, peer, exc)
        except asyncio.CancelledError:
            pass
        except Exception:  # one client's trouble never escapes as a task error
            log.exception("%s: client %s failed", self.name, peer)
        finally:
            self._writers.pop(writer, None)
            if not writer.transport.is_closing():
                writer.transport.close()


def _now() -> float:
    return asyncio.get_running_loop().time()


def _call_later(delay: float, callback: Any) -> object:
    """The event loop's ``call_later`` (the limiters' summaries come on time)."""
    try:
        return asyncio.get_running_loop().call_later(delay, callback)
    except RuntimeError:           # no loop (a server driven by hand): at the next event
        return None


def peer_text(peer: object) -> str:
    """``host:port`` of a peer address (``str`` of anything else)."""
    if isinstance(peer, tuple) and len(peer) >= 2:
        return f"{peer[0]}:{peer[1]}"
    return str(peer)
