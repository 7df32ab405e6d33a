"""The EtherNet/IP adapter as a transport: TCP 44818, UDP 44818 and UDP 2222 (docs/enip.md).

:class:`EnipTransport` is started by :class:`coolmuscle.transports.service.Service`
like every other transport and lives in its asyncio loop, so every model call
happens in the thread that drives the kernel, at the wall-clock instant now
(``Port.call``).  It joins the CM1 module (:mod:`.cm1`: the module over the device
API, its objects and description) to the CIP machinery (:mod:`.cip`) and owns only
sockets and timers:

* TCP: one :class:`~.cip.encapsulation.Connection` per client; a frame longer than the
  encapsulation limit is answered 0x0065 and the connection closed; a connection that
  brings no whole encapsulation packet for the TCP/IP object's encapsulation
  inactivity timeout (attribute 13, 120 s unless set; 0: never) is closed, and its
  session and class 3 connections end with it (CIP Vol 2 5-3);
* UDP on the TCP port number: ListIdentity / ListServices / ListInterfaces;
* UDP I/O port (2222): O->T packets in; T->O packets out, sent on time by the
  :class:`~.cip.producer.Producer` thread; a loop timer runs the watchdogs.  The
  connection table is shared under one lock.

``port=0`` / ``io_port=0`` pick free ports (tests); the UDP list port then takes the
TCP port's number.  Binds 127.0.0.1 unless told otherwise.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

from ...errors import TransportError
from ..transports.base import Port
from ..transports.stream_server import StreamServer
from .cip.encapsulation import (
    INVALID_LENGTH,
    Connection,
    Frame,
    FrameReader,
    FramingError,
    Sessions,
    answer_datagram,
)
from .cip.io import DEFAULT_IO_PORT, ConnectionTable
from .cip.producer import Producer
from .cip.router import Router
from .cm1.adapter import Cm1Module
from .cm1.objects import DESCRIPTION, ObjectModel
from .faults import EnipFaults

log = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 44818
READ_SIZE = 65536
IDLE_TICK = 0.1          # seconds between watchdog checks when nothing is due
PORT_ATTEMPTS = 5        # port 0: tries for a TCP port whose UDP twin is free
#: TCP clients served at once (encapsulation sessions need one each); one more is closed
#: as it arrives, so a flood cannot use up the file descriptors the motor's other
#: front ends share (docs/reliability.md "Bounds", as the text and Modbus TCP ports).
MAX_TCP_CLIENTS = 64


class _Datagrams(asyncio.DatagramProtocol):
    def __init__(self, handler: Callable[[bytes, tuple[str, int]], None]) -> None:
        self.handler = handler

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        try:
            self.handler(data, addr)
        except Exception:  # one bad datagram never stops the endpoint
            log.exception("enip: datagram from %s failed", addr)

    def error_received(self, exc: Exception) -> None:
        log.debug("enip: udp error %s", exc)


class EnipTransport(StreamServer):
    """Serve the CM1 EtherNet/IP module of motor ``motor`` (see module docstring)."""

    name = "enip"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 io_port: int = DEFAULT_IO_PORT, *, motor: int = 1,
                 priority: int | None = None) -> None:
        super().__init__(host, port, max_clients=MAX_TCP_CLIENTS)
        self.priority = priority
        self.requested_io_port = io_port
        self.motor = motor
        self.module: Cm1Module | None = None
        self.table: ConnectionTable | None = None
        self.router: Router | None = None
        self.sessions = Sessions()
        self.io_port = io_port
        self._udp: list[asyncio.DatagramTransport] = []
        self._io: asyncio.DatagramTransport | None = None
        self._handle: asyncio.TimerHandle | asyncio.Handle | None = None
        self._closed = True
        self.lock = threading.Lock()
        self.producer: Producer | None = None
        self._io_sock: socket.socket | None = None
        self.objects: ObjectModel | None = None
        self.faults: EnipFaults | None = None
        #: When each TCP connection last brought a whole encapsulation packet (monotonic s).
        self._last_packet: dict[asyncio.StreamWriter, float] = {}
        self.idle_closed = 0

    # -- life cycle -------------------------------------------------------------------------
    async def start(self, port: Port) -> None:
        self.port = port
        device = port.device
        if device is None:
            raise TransportError("enip: no device behind this port")
        self.module = Cm1Module(device, self.motor)
        self.table = ConnectionTable(self.module, DESCRIPTION, self.host, 0, port.call)
        self.faults = EnipFaults(device, port.call)         # docs/wire-faults.md
        self.table.open_check = self.faults.check_open
        self.table.t2o_lost = self.faults.lose_t2o
        objects = ObjectModel(self.module, host=self.host,
                              output_owned=lambda: self.table is not None
                              and self.table.owner is not None, reset=self._reset)
        self.objects = objects
        try:
            await self._listen()
        except OSError as exc:
            await self.close()
            raise TransportError(f"enip: cannot listen on {self.host} (TCP/UDP "
                                 f"{self.requested_port}, I/O UDP {self.requested_io_port}): "
                                 f"{exc.strerror or exc}") from exc
        self.table.io_port = self.io_port
        self.router = Router(objects, self.table, self.bound[1] if self.bound else 0,
                             call=port.call)
        self._closed = False
        assert self._io_sock is not None
        loop = asyncio.get_running_loop()
        self.producer = Producer(self.table, self._io_sock, self.lock,
                                 lambda: self._threadsafe(loop, self._refresh),
                                 self.priority)
        self.producer.start()
        self._schedule()

    async def _listen(self) -> None:
        for attempt in range(PORT_ATTEMPTS):
            try:
                await self._listen_tcp_udp()
                break
            except OSError:
                # a free TCP port whose UDP twin is taken: with port 0, try another
                if self.requested_port != 0 or attempt == PORT_ATTEMPTS - 1:
                    raise
        loop = asyncio.get_running_loop()
        io_sock = self._io_socket()
        io, _ = await loop.create_datagram_endpoint(lambda: _Datagrams(self._io_datagram),
                                                    sock=io_sock)
        self._io = io
        self._io_sock = io_sock
        self.io_port = io_sock.getsockname()[1]

    async def _listen_tcp_udp(self) -> None:
        """TCP and UDP on the same port number (44818)."""
        loop = asyncio.get_running_loop()
        server = await self.start_server()
        sockname = server.sockets[0].getsockname()
        try:
            udp, _ = await loop.create_datagram_endpoint(
                lambda: _Datagrams(self._list_datagram), local_addr=(self.host, sockname[1]))
        except OSError:
            server.close()
            await server.wait_closed()
            raise
        self._server, self.bound = server, (sockname[0], sockname[1])
        self._udp.append(udp)

    def _io_socket(self) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(self.host))
        except OSError:
            log.debug("enip: no multicast options on %s", self.host)
        try:
            sock.bind((self.host, self.requested_io_port))
        except OSError:
            sock.close()
            raise
        sock.setblocking(False)
        return sock

    def describe(self) -> str:
        return f"{super().describe()} (I/O udp {self.io_port})"

    def info(self) -> dict[str, Any]:
        return {**super().info(), "io_port": self.io_port}

    async def close(self) -> None:
        self._closed = True
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
        if self.producer is not None:
            await asyncio.get_running_loop().run_in_executor(None, self.producer.stop)
            self.producer = None
        if self.table is not None:
            with self.lock:
                self.table.close_all()
        await self.close_server()
        for udp in self._udp:
            udp.close()
        self._udp.clear()
        if self._io is not None:
            self._io.close()
            self._io = None
        self.finished.set()

    # -- TCP ---------------------------------------------------------------------------------
    def refuse(self, writer: asyncio.StreamWriter) -> None:
        writer.transport.abort()

    async def serve_connection(self, reader: asyncio.StreamReader,
                               writer: asyncio.StreamWriter, peer: str) -> None:
        assert self.router is not None
        remote = writer.get_extra_info("peername") or ("0.0.0.0", 0)
        local = writer.get_extra_info("sockname") or (self.host, 0)
        conn = Connection(self.router, self.sessions, (remote[0], remote[1]),
                          (local[0], local[1]))
        frames = FrameReader()
        self._last_packet[writer] = time.monotonic()
        try:
            while not conn.closing:
                data = await reader.read(READ_SIZE)
                if not data:
                    break
                frames.receive_data(data)
                if not self._answer_frames(conn, frames, writer):
                    break
                await writer.drain()
        finally:
            self._last_packet.pop(writer, None)
            with self.lock:
                conn.close()

    def _answer_frames(self, conn: Connection, frames: FrameReader,
                       writer: asyncio.StreamWriter) -> bool:
        """Answer every complete frame; ``False`` when the connection must close."""
        while not conn.closing:
            try:
                frame = frames.next_frame()
            except FramingError as exc:
                command, _, session, _, context, _ = exc.header
                writer.write(Frame(command, session, INVALID_LENGTH, context).encode())
                return False
            if frame is None:
                return True
            self._last_packet[writer] = time.monotonic()
            assert self.table is not None
            with self.lock:
                before = len(self.table.by_triad)
                reply = conn.handle(frame)
                changed = len(self.table.by_triad) != before
            if changed:
                self.wake()
            if reply is not None and not self.send(writer, reply):
                return False               # the peer reset: answer it no more
        return False

    # -- UDP -----------------------------------------------------------------------------------
    def _list_datagram(self, data: bytes, addr: tuple[str, int]) -> None:
        assert self.router is not None
        reply = answer_datagram(data, self.router, self.bound or (self.host, 0))
        if reply is not None and self._udp:
            self._udp[0].sendto(reply, addr)

    def _io_datagram(self, data: bytes, addr: tuple[str, int]) -> None:
        assert self.table is not None
        if self.faults is not None and self.faults.lose_o2t(data):
            return                        # lost on the wire: the watchdog runs on
        with self.lock:
            _accepted, output = self.table.accept(data, addr[0], time.monotonic_ns())
        if output is not None:          # the model's work, without the producer's lock
            self.table.write(output)

    def _tick(self) -> None:
        """Send what is due, time out the silent, then sleep until the next instant."""
        self._handle = None
        if self.table is None or self._closed:
            return
        try:
            with self.lock:
                gone = self.table.expire(time.monotonic_ns())
            if gone and self.producer is not None:
                self.producer.wake()
            if gone and self.faults is not None:
                self.faults.timed_out(gone)
            self._close_idle(time.monotonic())
        except Exception:  # the watchdogs must go on whatever one connection did
            log.exception("enip: I/O watchdog failed")
        self._schedule()

    def _close_idle(self, now: float) -> None:
        """Close the TCP connections silent for the encapsulation inactivity timeout
        (checked every tick, at most :data:`IDLE_TICK` late)."""
        timeout = self.objects.inactivity.seconds if self.objects is not None else 0
        if not timeout:
            return
        idle = [w for w, last in self._last_packet.items() if now - last >= timeout]
        for writer in idle:
            del self._last_packet[writer]
            self.idle_closed += 1
            log.debug("enip: closed a TCP connection with no encapsulation packet for %d s",
                      timeout)
            if writer.transport.get_write_buffer_size():
                writer.transport.abort()          # a client that does not read either
            else:
                writer.transport.close()

    def _schedule(self) -> None:
        assert self.table is not None
        loop = asyncio.get_running_loop()
        nxt = self.table.next_watchdog()
        when = loop.time() + IDLE_TICK if nxt is None else min(nxt / 1e9,
                                                                loop.time() + IDLE_TICK)
        self._handle = loop.call_at(when, self._tick)

    def wake(self) -> None:
        """Re-plan the timer and the producer now (a connection was opened or closed)."""
        if self._handle is not None:
            self._handle.cancel()
        self._handle = asyncio.get_running_loop().call_soon(self._tick)
        if self.producer is not None:
            self.producer.wake()

    def _reset(self) -> None:
        """Identity Reset: the module restarts (called under the lock, loop thread)."""
        assert self.table is not None and self.module is not None
        self.table.close_all()
        self.module.reset_outputs()
        self.wake()

    def _refresh(self) -> None:
        """Read the input image for the next T->O packets (loop thread)."""
        if self.table is None or self._closed:
            return
        try:
            self.table.refresh()
        except Exception:
            log.exception("enip: reading the input image failed")

    @staticmethod
    def _threadsafe(loop: asyncio.AbstractEventLoop, fn: Callable[[], None]) -> None:
        try:
            loop.call_soon_threadsafe(fn)
        except RuntimeError:     # the loop is closing
            pass
