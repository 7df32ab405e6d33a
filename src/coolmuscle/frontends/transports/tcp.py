"""TCP server transport: the host line over a socket, several clients at once.

Owns the asyncio TCP server (default bind 127.0.0.1:5150, docs/transports.md):

* every client's bytes go to the host line through its own
  :class:`~coolmuscle.frontends.transports.base.Lane`: its lines are assembled
  apart from every other client's and run whole, in turn with the others, so a
  client that floods or leaves a line unfinished never delays the others' lines
  by more than one turn (docs/reliability.md);
* every byte the motor sends goes to every client, so each one sees echoes,
  replies and events;
* **bounded output**: a client with more than ``max_buffer`` bytes it has not
  read (what the socket would not take) is dropped, never waited for: the motor
  is not blocked by a slow reader, and only a client that fails to read is
  dropped.  A client whose own output backs up stops being read (TCP back
  pressure to it alone);
* **connection limit and idle policy**: with every one of the ``max_clients``
  places taken, a new client is admitted by closing the connection idle longest
  among those that never sent a whole line or sent none for ``idle_timeout``
  seconds (it gets one line ``coolmuscle: connection closed: silent for N s while
  all N places were taken``); when every connection is in use the new client gets
  ``coolmuscle: too many clients (N); connection refused`` and is closed
  (:mod:`.stream_server`, docs/reliability.md "Connections");
* a client's disconnect, reset or garbage never affects the others; a bank
  upload it opened ends with it.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

from ...errors import TransportError
from .base import DEFAULT_MAX_BUFFER, Lane, Port
from .lograte import LogLimiter
from .stream_server import DEFAULT_IDLE_TIMEOUT, DEFAULT_MAX_CLIENTS, StreamServer

log = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 5150

READ_SIZE = 4096
#: Lines a client's connect and disconnect may log per window (``-v``) before a summary.
CONNECTION_LINES = 20


def parse_address(text: str, default_host: str = DEFAULT_HOST) -> tuple[str, int]:
    """``"5150"`` / ``"0.0.0.0:5150"`` / ``"[::1]:5150"`` -> ``(host, port)``."""
    text = text.strip()
    host, sep, port_text = text.rpartition(":")
    if not sep:
        host, port_text = default_host, text
    host = host.strip("[]") or default_host
    try:
        port = int(port_text)
    except ValueError:
        raise TransportError(f"bad TCP address {text!r}: expected [HOST:]PORT") from None
    if not 0 <= port <= 65535:
        raise TransportError(f"bad TCP port {port} (0..65535)")
    return host, port


class _Client:
    """One connected host: its stream, its input lane and its output queue."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                 lane: Lane, peer: str) -> None:
        self.reader = reader
        self.writer = writer
        self.lane = lane
        self.peer = peer
        self.pending = bytearray()
        self.flush_scheduled = False
        self.dropped = False
        self.spoke = False              # it sent a whole line (idle policy)

    def unread(self) -> int:
        """Bytes handed to the socket that it did not take (the client did not read)."""
        transport = self.writer.transport
        return 0 if transport.is_closing() else transport.get_write_buffer_size()


class TcpTransport(StreamServer):
    """Serve the host line to TCP clients (see module docstring for the rules)."""

    name = "tcp"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 max_buffer: int = DEFAULT_MAX_BUFFER,
                 max_clients: int = DEFAULT_MAX_CLIENTS,
                 idle_timeout: float | None = DEFAULT_IDLE_TIMEOUT) -> None:
        super().__init__(host, port, max_clients=max_clients, idle_timeout=idle_timeout)
        self.max_buffer = max_buffer
        self._clients: list[_Client] = []
        self._unsubscribe: Callable[[], None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.dropped_clients = 0
        self._log_connection = LogLimiter(log, logging.INFO, "connects and disconnects",
                                          burst=CONNECTION_LINES)
        self._log_dropped = LogLimiter(log, logging.WARNING, "slow clients dropped")

    # -- life cycle -----------------------------------------------------
    async def start(self, port: Port) -> None:
        self.port = port
        self._loop = asyncio.get_running_loop()
        await self.listen()
        self._unsubscribe = port.add_listener(self._broadcast)

    @property
    def clients(self) -> int:
        """Number of connected clients."""
        return len(self._clients)

    async def close(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        await self.close_server()
        self.finished.set()

    # -- input ----------------------------------------------------------
    def refuse(self, writer: asyncio.StreamWriter) -> None:
        writer.write(b"coolmuscle: too many clients (%d); connection refused\r\n"
                     % self.max_clients)
        writer.close()

    def evict(self, writer: asyncio.StreamWriter, idle: float) -> None:
        if writer.transport.get_write_buffer_size():
            writer.transport.abort()            # it does not read: nothing more to say
            return
        writer.write(b"coolmuscle: connection closed: %s for %d s while all %d places "
                     b"were taken\r\n" % (b"idle" if self._spoke(writer) else b"silent",
                                           idle, self.max_clients))
        writer.close()

    def _spoke(self, writer: asyncio.StreamWriter) -> bool:
        return any(client.writer is writer and client.spoke for client in self._clients)

    async def serve_connection(self, reader: asyncio.StreamReader,
                               writer: asyncio.StreamWriter, peer: str) -> None:
        assert self.port is not None
        client = _Client(reader, writer, self.port.open_lane("tcp"), peer)
        room = asyncio.Event()
        room.set()
        client.lane.set_flow(room.clear, room.set)
        self._clients.append(client)
        self._log_connection("tcp: client %s connected", client.peer)
        try:
            while not client.dropped:
                data = await reader.read(READ_SIZE)
                if not data:
                    break
                if b"\r" in data or b"\n" in data:   # a whole line: in use (idle policy)
                    client.spoke = True
                    self.request_seen(writer)
                client.lane.feed(data)
                await room.wait()           # its lines wait their turn: read no further
                if client.unread() and not client.dropped:
                    await writer.drain()    # its own output backs up: stop reading it
        finally:
            self._clients.remove(client)
            client.lane.close()         # its half line and its bank upload end with it
            self._log_connection("tcp: client %s disconnected", client.peer)

    # -- output ---------------------------------------------------------
    def _broadcast(self, data: bytes) -> None:
        for client in list(self._clients):
            if client.dropped:
                continue
            client.pending += data
            if len(client.pending) >= self.max_buffer:
                self._flush(client)     # hand it to the socket now; judge what it takes
            elif not client.flush_scheduled and self._loop is not None:
                client.flush_scheduled = True
                self._loop.call_soon(self._flush, client)

    def _flush(self, client: _Client) -> None:
        client.flush_scheduled = False
        if client.dropped or not client.pending:
            return
        data = bytes(client.pending)
        client.pending.clear()
        if not self.send(client.writer, data):
            return
        if client.unread() > self.max_buffer:
            self._drop(client)

    def _drop(self, client: _Client) -> None:
        client.dropped = True
        client.pending.clear()
        self.dropped_clients += 1
        self._log_dropped("tcp: dropped client %s: more than %d bytes of output unread",
                          client.peer, self.max_buffer)
        client.writer.transport.abort()
