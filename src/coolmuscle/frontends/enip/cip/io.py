"""Class 1 implicit I/O and class 3 connections: the connection table (CIP Vol 1 3-4, Vol 2 3-3).

Sans-socket: the server passes the monotonic time (ns) in and sends what comes out.
What the adapter offers (identity, the one Class 1 connection, how many connections)
is its :class:`~.description.AdapterDescription`; what it drives is a :class:`Module`.

* Class 1 exclusive owner of the offered connection (output -> input assembly): O->T
  point-to-point, with the 32-bit run/idle header when its size says so (4 more
  bytes) or modeless;
  T->O point-to-point to the originator's address (port 2222 or the port of its
  T->O sockaddr item) or multicast (CIP Vol 2 3-5.3 address, port of the server).
* Every T->O production carries the sequenced address item (32-bit encapsulation
  sequence number, +1 a packet) and the 16-bit CIP sequence count (+1 a
  production, cyclic trigger).  Productions follow an absolute schedule
  (open time + k·RPI), so lateness never accumulates.
* An O->T packet is accepted from the originator's IP only, with the connection's
  exact size and a sequence number newer than the last (modulo 2^32); an unchanged
  CIP sequence count is not new data.  Each accepted packet restarts the
  inactivity watchdog: O->T RPI × 4·2^multiplier.  On expiry the connection closes,
  production stops, the module's outputs go back to their power-up image and its
  I/O state is "faulted" until a connection opens again (Identity extended status 2).
* Class 3 (explicit, to the Message Router) connections belong to the TCP session
  that opened them; a repeated sequence count gets the previous reply again.
* Each kind has its own limit (the description's ``max_io_connections`` and
  ``max_msg_connections``, the EDS's [Capacity]): idle class 3 connections never
  keep a PLC's Class 1 connection out.  One kind full: 0x01/0x0113 "out of
  connections" (CIP Vol 1 table 3-5.33); a second exclusive owner of the one I/O
  connection point: 0x01/0x0106 "ownership conflict", as before.
"""

from __future__ import annotations

import ipaddress
import logging
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal, Protocol, TypeVar

from . import connmgr
from . import messages as cip
from .description import AdapterDescription
from .encapsulation import (
    ITEM_CONNECTED_DATA,
    ITEM_SEQUENCED_ADDRESS,
    ITEM_SOCKADDR_OT,
    ITEM_SOCKADDR_TO,
    CpfError,
    Item,
    encode_cpf,
    parse_cpf,
    parse_sockaddr,
    sockaddr,
)
from .messages import CipError

log = logging.getLogger(__name__)

DEFAULT_IO_PORT = 2222
NS_PER_US = 1_000
RUN_BIT = 0x0001
MULTICAST_BASE = int(ipaddress.IPv4Address("239.192.1.0"))


@dataclass(slots=True)
class Connection:
    """One open connection, class 1 or class 3."""

    req: connmgr.OpenRequest
    ot_id: int
    to_id: int
    peer_ip: str
    session: int = 0
    header: bool = True
    to_addr: tuple[str, int] | None = None
    multicast: bool = False
    last_rx: int = 0
    ot_seq: int | None = None
    ot_count: int | None = None
    to_seq: int = 0
    to_count: int = 0
    next_due: int = 0
    last_reply: tuple[int, bytes] | None = None
    packets_in: int = 0
    packets_out: int = 0
    #: the next T->O packet is lost on the way (:attr:`ConnectionTable.t2o_lost`)
    lose_next: bool = False

    @property
    def io(self) -> bool:
        return self.req.transport_class == 1

    @property
    def timeout_ns(self) -> int:
        return self.req.timeout_us * NS_PER_US

    @property
    def to_rpi_ns(self) -> int:
        return self.req.to_rpi * NS_PER_US


_T = TypeVar("_T")


class Call(Protocol):
    """How the table reaches the model: ``call(fn, *args)`` runs ``fn`` in the model's
    thread at the wall-clock instant now (``Port.call``) and returns what it returns."""

    def __call__(self, fn: Callable[..., _T], /, *args: Any) -> _T: ...


def direct(fn: Callable[..., _T], /, *args: Any) -> _T:
    """A :class:`Call` for a caller already in the model's thread (tests)."""
    return fn(*args)


#: The I/O state the table gives the module (Identity status, CIP Vol 1 5A-2.2).
IoState = Literal["none", "run", "idle", "faulted"]


class Module(Protocol):
    """What the table drives in the product's module: its images and I/O state."""

    io_state: IoState

    def input_image(self) -> bytes: ...

    def write_output(self, data: bytes, run: bool = True) -> None: ...

    def reset_outputs(self) -> None: ...


def multicast_address(host: str) -> str:
    """The T->O multicast group of CIP Vol 2 3-5.3 for the adapter's address."""
    try:
        ip = int(ipaddress.IPv4Address(host))
    except ValueError:
        ip = 1
    mask = 0xFF000000 if ip >> 24 == 127 else 0xFFFFFF00
    host_id = ip & ~mask & 0xFFFFFFFF
    return str(ipaddress.IPv4Address(MULTICAST_BASE + ((host_id - 1) & 0x3FF) * 32))


class ConnectionTable:
    """Open, close, consume, produce and time out connections."""

    def __init__(self, module: Module, adapter: AdapterDescription, host: str, io_port: int,
                 call: Call = direct) -> None:
        self.module = module
        self.adapter = adapter
        self.host = host
        self.io_port = io_port
        self.call = call
        self.by_triad: dict[tuple[int, int, int], Connection] = {}
        self.by_ot: dict[int, Connection] = {}
        self._next_id = 0x5A00_0000 ^ (id(self) & 0x00FF_FFF0)
        self.timeouts = 0
        self.dropped = 0
        self.lost = 0
        #: Asked before a Forward_Open is served: raises ``CipError`` to refuse it (the
        #: product's wire faults); ``None``: every open is judged on its own merits.
        self.open_check: Callable[[connmgr.OpenRequest], None] | None = None
        #: Asked at each refresh, in the model's thread: whether the next T->O packet of
        #: a connection is lost on the wire (it is produced and counted, not sent).
        self.t2o_lost: Callable[[Connection], bool] | None = None
        #: The input image productions send; refreshed by the loop (:meth:`refresh`).
        self.image = bytes(adapter.connection.input_size)

    # -- opening and closing ------------------------------------------------------------
    def _new_id(self) -> int:
        self._next_id = (self._next_id + 1) & 0xFFFFFFFF or 1
        return self._next_id

    def count(self, io: bool) -> int:
        """Open connections of one kind: class 1 (``io``) or class 3."""
        return sum(1 for c in self.by_triad.values() if c.io == io)

    @property
    def owner(self) -> Connection | None:
        return next((c for c in self.by_triad.values() if c.io), None)

    def open(self, req: connmgr.OpenRequest, peer_ip: str, session: int, items: list[Item],
             now: int) -> tuple[bytes, list[Item]]:
        """Forward_Open: the reply body and the CPF items to send with it."""
        if req.triad in self.by_triad:
            raise req.failure(connmgr.DUPLICATE)
        if self.open_check is not None:
            self.open_check(req)
        if req.transport_class == 3:
            connmgr.check_class3(req, self.adapter.identity)
            if self.count(io=False) >= self.adapter.max_msg_connections:
                raise req.failure(connmgr.OUT_OF_CONNECTIONS)
            conn = Connection(req, self._new_id(), req.to_id, peer_ip, session)
            return self._register(conn, now), []
        header = connmgr.check_class1(req, self.adapter.identity, self.adapter.connection)
        if self.owner is not None:
            raise req.failure(connmgr.OWNERSHIP_CONFLICT)
        if self.count(io=True) >= self.adapter.max_io_connections:
            raise req.failure(connmgr.OUT_OF_CONNECTIONS)
        conn = Connection(req, self._new_id(), req.to_id, peer_ip, 0, header)
        extra = self._route_to(conn, items)
        conn.next_due = now
        self.refresh()
        body = self._register(conn, now)
        self.module.io_state = "run"
        return body, extra

    def _route_to(self, conn: Connection, items: list[Item]) -> list[Item]:
        """Where T->O goes, and the sockaddr items of the reply (CIP Vol 2 3-3.9)."""
        port = DEFAULT_IO_PORT
        for item in items:
            if item.type_id == ITEM_SOCKADDR_TO:
                info = parse_sockaddr(item.data)
                if info is not None and info[0]:
                    port = info[0]
        extra = []
        if conn.req.to.type == connmgr.MULTICAST:
            group = multicast_address(self.host)
            conn.to_id, conn.multicast = self._new_id(), True
            conn.to_addr = (group, self.io_port)
            extra.append(Item(ITEM_SOCKADDR_TO, sockaddr(
                self.io_port, int(ipaddress.IPv4Address(group)))))
        else:
            conn.to_addr = (conn.peer_ip, port)
        if self.io_port != DEFAULT_IO_PORT:
            extra.append(Item(ITEM_SOCKADDR_OT, sockaddr(self.io_port)))
        return extra

    def _register(self, conn: Connection, now: int) -> bytes:
        conn.last_rx = now
        self.by_triad[conn.req.triad] = conn
        self.by_ot[conn.ot_id] = conn
        req = conn.req
        log.info("enip: class %d connection %08X/%08X opened (RPI %d/%d us)",
                 req.transport_class, conn.ot_id, conn.to_id, req.ot_rpi, req.to_rpi)
        return connmgr.open_reply(req, conn.ot_id, conn.to_id, req.ot_rpi, req.to_rpi)

    def close(self, data: bytes) -> bytes:
        """Forward_Close: the reply body (raises ``CipError`` 0x01/0x0107 if unknown)."""
        triad, _path = connmgr.parse_close(data)
        conn = self.by_triad.get(triad)
        if conn is None:
            raise connmgr.close_failure(triad)
        self._drop(conn)
        return connmgr.close_reply(triad)

    def _drop(self, conn: Connection) -> None:
        self.by_triad.pop(conn.req.triad, None)
        self.by_ot.pop(conn.ot_id, None)
        if conn.io:
            self.module.reset_outputs()
            self.module.io_state = "none"

    def session_closed(self, session: int) -> None:
        for conn in [c for c in self.by_triad.values() if not c.io and c.session == session]:
            self._drop(conn)

    def close_all(self) -> None:
        for conn in list(self.by_triad.values()):
            self._drop(conn)

    # -- class 1 consumption and production ----------------------------------------------
    def consume(self, datagram: bytes, source_ip: str, now: int) -> bool:
        """One O->T datagram; ``True`` when it was accepted.  New data goes to the module."""
        accepted, output = self.accept(datagram, source_ip, now)
        if output is not None:
            self.write(output)
        return accepted

    def accept(self, datagram: bytes, source_ip: str,
               now: int) -> tuple[bool, tuple[bytes, bool] | None]:
        """Check one O->T datagram against the table and restart its watchdog: whether
        it was accepted, and the new output image with its run flag (``None`` when the
        data is not new).  Touches the table only, so the server holds the table's
        lock for this and writes the image to the module after letting it go."""
        try:
            items = parse_cpf(datagram)
        except CpfError:
            self.dropped += 1
            return False, None
        if (len(items) != 2 or items[0].type_id != ITEM_SEQUENCED_ADDRESS
                or len(items[0].data) != 8 or items[1].type_id != ITEM_CONNECTED_DATA):
            self.dropped += 1
            return False, None
        conn_id, seq = struct.unpack("<II", items[0].data)
        conn = self.by_ot.get(conn_id)
        if conn is None or not conn.io or source_ip != conn.peer_ip \
                or len(items[1].data) != conn.req.ot.size:
            self.dropped += 1
            return False, None
        if conn.ot_seq is not None and not 0 < (seq - conn.ot_seq) & 0xFFFFFFFF < 0x80000000:
            return False, None                    # old or repeated packet
        conn.ot_seq, conn.last_rx = seq, now
        conn.packets_in += 1
        return True, self._new_output(conn, items[1].data)

    def _new_output(self, conn: Connection, data: bytes) -> tuple[bytes, bool] | None:
        count = struct.unpack_from("<H", data)[0]
        if count == conn.ot_count:
            return None                             # same data again (3-4.4.2)
        conn.ot_count = count
        run, body = True, data[2:]
        if conn.header:
            run = bool(struct.unpack_from("<I", body)[0] & RUN_BIT)
            body = body[4:]
        return body, run

    def write(self, output: tuple[bytes, bool]) -> None:
        """Give the module an output image from :meth:`accept` (the model's thread)."""
        body, run = output
        self.module.io_state = "run" if run else "idle"
        self.call(self.module.write_output, body, run)

    def refresh(self) -> None:
        """Read the input image from the module (the model's thread only); ask which
        connections lose their next T->O packet."""
        self.image = bytes(self.call(self.module.input_image))
        lost = self.t2o_lost
        if lost is not None:
            for conn in list(self.by_triad.values()):
                if conn.io and not conn.lose_next:
                    conn.lose_next = lost(conn)

    def next_production(self) -> int | None:
        """The earliest T->O production instant (ns), ``None`` without class 1."""
        times = [c.next_due for c in self.by_triad.values() if c.io]
        return min(times) if times else None

    def due(self, now: int) -> list[tuple[bytes, tuple[str, int]]]:
        """The T->O packets due at ``now`` with the last refreshed image; moves each
        schedule on.  Touches no model object, so a producer thread may call it."""
        out = []
        for conn in list(self.by_triad.values()):
            if not conn.io or conn.to_addr is None or now < conn.next_due:
                continue
            packet = self._packet(conn, self.image)
            if conn.lose_next:              # produced, lost on the way
                conn.lose_next = False
                self.lost += 1
            else:
                out.append((packet, conn.to_addr))
            rpi = conn.to_rpi_ns
            conn.next_due += rpi
            if conn.next_due <= now:                 # more than one RPI late: no burst
                conn.next_due = now + rpi - (now - conn.next_due) % rpi
        return out

    def _packet(self, conn: Connection, data: bytes) -> bytes:
        conn.to_seq = (conn.to_seq + 1) & 0xFFFFFFFF
        conn.to_count = (conn.to_count + 1) & 0xFFFF
        conn.packets_out += 1
        return encode_cpf([
            Item(ITEM_SEQUENCED_ADDRESS, struct.pack("<II", conn.to_id, conn.to_seq)),
            Item(ITEM_CONNECTED_DATA, struct.pack("<H", conn.to_count) + data)])

    def expire(self, now: int) -> list[Connection]:
        """Close every connection whose watchdog ran out (CIP Vol 1 3-4.5.3)."""
        gone = [c for c in self.by_triad.values() if now - c.last_rx > c.timeout_ns]
        for conn in gone:
            self.timeouts += 1
            log.info("enip: connection %08X timed out", conn.ot_id)
            self._drop(conn)
            if conn.io:           # Identity status: a faulted I/O connection (CIP 5A-2.2)
                self.module.io_state = "faulted"
        return gone

    def next_watchdog(self) -> int | None:
        """The earliest watchdog instant (ns), ``None`` without connections."""
        times = [c.last_rx + c.timeout_ns + 1 for c in self.by_triad.values()]
        return min(times) if times else None

    # -- class 3 -----------------------------------------------------------------------------
    def connected(self, conn_id: int, data: bytes, session: int, now: int,
                  answer: Callable[[bytes], bytes]) -> tuple[int, bytes] | None:
        """SendUnitData on a class 3 connection: ``(T->O id, sequence + reply)``."""
        conn = self.by_ot.get(conn_id)
        if conn is None or conn.io or conn.session != session or len(data) < 2:
            return None
        conn.last_rx = now
        count = data[:2]
        if conn.last_reply is not None and conn.last_reply[0] == struct.unpack("<H", count)[0]:
            return conn.to_id, count + conn.last_reply[1]
        reply = answer(data[2:])
        conn.last_reply = (struct.unpack("<H", count)[0], reply)
        return conn.to_id, count + reply


def open_or_error(table: ConnectionTable, request: cip.Request, peer_ip: str, session: int,
                  items: list[Item], now: int) -> tuple[bytes, list[Item]]:
    """Forward_Open / Large_Forward_Open service handler (raises ``CipError``)."""
    large = request.service == cip.LARGE_FORWARD_OPEN
    req = connmgr.parse_open(request.data, large)
    return table.open(req, peer_ip, session, items, now)


__all__ = ["CipError", "Connection", "ConnectionTable", "DEFAULT_IO_PORT", "open_or_error"]
