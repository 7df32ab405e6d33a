"""TCP server transport: the host line over a socket, several clients at once.

Owns the asyncio TCP server (default bind 127.0.0.1:5150, docs/transports.md):

* every client's bytes go to the host line (``Port.feed``); every byte the motor
  sends goes to every client, so each one sees echoes, replies and events;
* **line ownership**: a client whose input stops in the middle of a line owns the
  line until it sends the line end (or disconnects, or stays silent for ``hold``
  seconds while others wait).  Other clients' bytes wait meanwhile (TCP back
  pressure), so lines from different clients are never interleaved byte-wise;
* **bounded output**: each client has at most ``max_buffer`` bytes queued and
  unsent.  A client that does not read fast enough is dropped, never waited for:
  the motor is not blocked by a slow reader;
* a client's disconnect, reset or garbage never affects the others.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from ...errors import TransportError
from .base import DEFAULT_MAX_BUFFER, Port, Transport, ends_mid_line

log = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 5150

#: Seconds a silent client keeps the line while it is in the middle of a line
#: and another client is waiting.
DEFAULT_HOLD = 2.0

READ_SIZE = 4096


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
    """One connected host: its stream and its bounded output queue."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader = reader
        self.writer = writer
        peer = writer.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)
        self.pending = bytearray()
        self.flush_scheduled = False
        self.dropped = False
        self.mid_line = False
        self.ended_with_cr = False
        self.last_input = 0.0

    def queued(self) -> int:
        transport = self.writer.transport
        buffered = 0 if transport.is_closing() else transport.get_write_buffer_size()
        return len(self.pending) + buffered


class TcpTransport(Transport):
    """Serve the host line to TCP clients (see module docstring for the rules)."""

    name = "tcp"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 max_buffer: int = DEFAULT_MAX_BUFFER, hold: float = DEFAULT_HOLD) -> None:
        super().__init__()
        self.host = host
        self.requested_port = port
        self.max_buffer = max_buffer
        self.hold = hold
        self._server: asyncio.base_events.Server | None = None
        self._clients: list[_Client] = []
        self._owner: _Client | None = None
        self._last_feeder: _Client | None = None
        self._released = asyncio.Event()
        self._unsubscribe: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.bound: tuple[str, int] | None = None
        self.dropped_clients = 0

    # -- life cycle -----------------------------------------------------
    async def start(self, port: Port) -> None:
        self.port = port
        self._loop = asyncio.get_running_loop()
        try:
            self._server = await asyncio.start_server(self._serve_client, self.host,
                                                      self.requested_port)
        except OSError as exc:
            raise TransportError(f"tcp: cannot listen on {self.host}:{self.requested_port}: "
                                 f"{exc.strerror or exc}") from exc
        sockname = self._server.sockets[0].getsockname()
        self.bound = (sockname[0], sockname[1])
        self._unsubscribe = port.add_listener(self._broadcast)

    def describe(self) -> str:
        host, port = self.bound or (self.host, self.requested_port)
        return f"tcp: [{host}]:{port}" if ":" in host else f"tcp: {host}:{port}"

    def info(self) -> dict[str, Any]:
        host, port = self.bound or (self.host, self.requested_port)
        return {"host": host, "port": port}

    @property
    def clients(self) -> int:
        """Number of connected clients."""
        return len(self._clients)

    async def close(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self._server is not None:
            self._server.close()
        for client in list(self._clients):
            client.writer.transport.abort()
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None
        self.finished.set()

    # -- input ----------------------------------------------------------
    async def _serve_client(self, reader: asyncio.StreamReader,
                            writer: asyncio.StreamWriter) -> None:
        client = _Client(reader, writer)
        self._clients.append(client)
        log.info("tcp: client %s connected", client.peer)
        try:
            while not client.dropped:
                data = await reader.read(READ_SIZE)
                if not data:
                    break
                await self._take_line(client)
                if client.dropped:
                    break
                assert self.port is not None
                if (data[:1] == b"\n" and client.ended_with_cr
                        and self._last_feeder not in (None, client)):
                    data = data[1:]   # the rest of this client's CRLF, after someone else's line
                self._last_feeder = client
                self.port.feed(data)
                client.last_input = self._now()
                client.mid_line = ends_mid_line(data)
                client.ended_with_cr = data[-1:] == b"\r"
                if client.mid_line:
                    self._owner = client
                elif self._owner is client:
                    self._release()
        except (ConnectionError, OSError) as exc:
            log.info("tcp: client %s: %s", client.peer, exc)
        except asyncio.CancelledError:
            pass
        except Exception:  # never let one client's trouble escape as a task error
            log.exception("tcp: client %s failed", client.peer)
        finally:
            self._forget(client)

    async def _take_line(self, client: _Client) -> None:
        """Wait while another client is in the middle of a line (at most ``hold`` idle)."""
        while self._owner is not None and self._owner is not client:
            owner = self._owner
            remaining = owner.last_input + self.hold - self._now()
            if remaining <= 0:
                log.info("tcp: client %s idle mid-line for %.1f s; line released",
                         owner.peer, self.hold)
                self._release()
                return
            self._released.clear()
            try:
                await asyncio.wait_for(self._released.wait(), remaining)
            except (asyncio.TimeoutError, TimeoutError):
                pass

    def _release(self) -> None:
        self._owner = None
        self._released.set()

    def _forget(self, client: _Client) -> None:
        if client in self._clients:
            self._clients.remove(client)
        if self._last_feeder is client:
            self._last_feeder = None
        if self._owner is client:
            # The departed client's half line must not prefix the next client's line.
            if self.port is not None and client.mid_line:
                self.port.discard_partial()
            self._release()
        if not client.writer.transport.is_closing():
            client.writer.transport.close()
        log.info("tcp: client %s disconnected", client.peer)

    def _now(self) -> float:
        return self._loop.time() if self._loop is not None else 0.0

    # -- output ---------------------------------------------------------
    def _broadcast(self, data: bytes) -> None:
        for client in list(self._clients):
            if client.dropped:
                continue
            if client.queued() + len(data) > self.max_buffer:
                self._drop(client)
                continue
            client.pending += data
            if not client.flush_scheduled and self._loop is not None:
                client.flush_scheduled = True
                self._loop.call_soon(self._flush, client)

    def _flush(self, client: _Client) -> None:
        client.flush_scheduled = False
        if client.dropped or not client.pending:
            return
        data = bytes(client.pending)
        client.pending.clear()
        if not client.writer.transport.is_closing():
            client.writer.write(data)

    def _drop(self, client: _Client) -> None:
        client.dropped = True
        client.pending.clear()
        self.dropped_clients += 1
        log.warning("tcp: dropped client %s: more than %d bytes of output unread",
                    client.peer, self.max_buffer)
        client.writer.transport.abort()
