"""EtherNet/IP encapsulation (CIP Vol 2 ch. 2): framing, sessions, common packet format.

Sans-IO in the manner of h11: :class:`FrameReader` is fed bytes and hands back
:class:`Frame` objects; :class:`Connection` turns one request frame into the reply
bytes (or none) and says when the TCP connection must close.  No socket and no
clock live here; :mod:`..server` owns those, :mod:`.router` answers the CIP inside.

Rules kept (CIP Vol 2 2-3, 2-4, 2-5):

* the 24-byte header is little endian: command, length, session handle, status,
  sender context (echoed), options; a request with options or status not zero is
  discarded;
* an unknown command gets status 0x0001 with the header echoed; a frame longer
  than :data:`MAX_LENGTH` gets 0x0065 and the connection closes (its framing is
  lost); a SendRRData / SendUnitData whose session handle is not the one this TCP
  connection registered gets 0x0064 and touches nobody's session;
* RegisterSession takes exactly 4 bytes (protocol version 1): other lengths 0x0065,
  other versions 0x0069, a second registration on the same connection 0x0003;
  UnRegisterSession has no reply and closes the connection;
* NOP has no reply; ListIdentity, ListServices and ListInterfaces need no session
  and are also answered over UDP (:func:`answer_datagram`).
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass, field
from typing import Any, Protocol

log = logging.getLogger(__name__)

HEADER = struct.Struct("<HHII8sI")
HEADER_SIZE = HEADER.size
#: Longest encapsulated data accepted (a CIP explicit message fits in 600 bytes).
MAX_LENGTH = 4096
PROTOCOL_VERSION = 1

# commands (CIP Vol 2 table 2-3.2)
NOP = 0x0000
LIST_SERVICES = 0x0004
LIST_IDENTITY = 0x0063
LIST_INTERFACES = 0x0064
REGISTER_SESSION = 0x0065
UNREGISTER_SESSION = 0x0066
SEND_RR_DATA = 0x006F
SEND_UNIT_DATA = 0x0070

# status (CIP Vol 2 table 2-3.3)
OK = 0x0000
INVALID_COMMAND = 0x0001
NO_MEMORY = 0x0002
INCORRECT_DATA = 0x0003
INVALID_SESSION = 0x0064
INVALID_LENGTH = 0x0065
UNSUPPORTED_PROTOCOL = 0x0069

# common packet format item types (CIP Vol 2 table 2-6.3)
ITEM_NULL = 0x0000
ITEM_IDENTITY = 0x000C
ITEM_CONNECTED_ADDRESS = 0x00A1
ITEM_CONNECTED_DATA = 0x00B1
ITEM_UNCONNECTED_DATA = 0x00B2
ITEM_SERVICES = 0x0100
ITEM_SOCKADDR_OT = 0x8000
ITEM_SOCKADDR_TO = 0x8001
ITEM_SEQUENCED_ADDRESS = 0x8002

#: ListServices capability flags: CIP over TCP (bit 5), class 0/1 over UDP (bit 8).
SERVICE_CAPABILITIES = 0x0120


class FramingError(Exception):
    """The stream cannot be framed any more (length beyond :data:`MAX_LENGTH`)."""

    def __init__(self, header: tuple[Any, ...]) -> None:
        super().__init__("encapsulation length out of range")
        self.header = header


@dataclass(frozen=True, slots=True)
class Frame:
    """One encapsulation packet."""

    command: int
    session: int = 0
    status: int = 0
    context: bytes = bytes(8)
    options: int = 0
    data: bytes = b""

    def encode(self) -> bytes:
        return HEADER.pack(self.command, len(self.data), self.session, self.status,
                           self.context, self.options) + self.data

    def reply(self, data: bytes = b"", status: int = OK, session: int | None = None) -> bytes:
        """The reply frame: same command and context, ``data`` and ``status``."""
        return Frame(self.command, self.session if session is None else session, status,
                     self.context, 0, data).encode()


def decode_frame(buf: bytes) -> Frame | None:
    """One whole frame from a datagram (``None`` when short or inconsistent)."""
    if len(buf) < HEADER_SIZE:
        return None
    command, length, session, status, context, options = HEADER.unpack_from(buf)
    if HEADER_SIZE + length != len(buf):
        return None
    return Frame(command, session, status, context, options, bytes(buf[HEADER_SIZE:]))


class FrameReader:
    """Stream to frames: ``receive_data`` then ``next_frame`` until it returns ``None``."""

    def __init__(self, max_length: int = MAX_LENGTH) -> None:
        self._buf = bytearray()
        self.max_length = max_length

    def receive_data(self, data: bytes) -> None:
        self._buf += data

    def next_frame(self) -> Frame | None:
        """The next complete frame; raises :class:`FramingError` on a bad length."""
        if len(self._buf) < HEADER_SIZE:
            return None
        header = HEADER.unpack_from(self._buf)
        length = header[1]
        if length > self.max_length:
            raise FramingError(header)
        if len(self._buf) < HEADER_SIZE + length:
            return None
        data = bytes(self._buf[HEADER_SIZE:HEADER_SIZE + length])
        del self._buf[:HEADER_SIZE + length]
        command, _, session, status, context, options = header
        return Frame(command, session, status, context, options, data)


# -- common packet format --------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Item:
    """One common packet format item."""

    type_id: int
    data: bytes = b""


class CpfError(ValueError):
    """A common packet format that does not add up."""


def parse_cpf(buf: bytes) -> list[Item]:
    """Item count, then each item's type, length and data; the items must fill ``buf``."""
    if len(buf) < 2:
        raise CpfError("no item count")
    count, pos, items = struct.unpack_from("<H", buf)[0], 2, []
    for _ in range(count):
        if pos + 4 > len(buf):
            raise CpfError("truncated item header")
        type_id, length = struct.unpack_from("<HH", buf, pos)
        pos += 4
        if pos + length > len(buf):
            raise CpfError("truncated item")
        items.append(Item(type_id, bytes(buf[pos:pos + length])))
        pos += length
    if pos != len(buf):
        raise CpfError("bytes after the last item")
    return items


def encode_cpf(items: list[Item]) -> bytes:
    out = bytearray(struct.pack("<H", len(items)))
    for item in items:
        out += struct.pack("<HH", item.type_id, len(item.data)) + item.data
    return bytes(out)


def sockaddr(port: int, address: int = 0) -> bytes:
    """A sockaddr info item body (big endian, as the spec says: CIP Vol 2 2-6.3.3)."""
    return struct.pack(">hHI8x", 2, port, address)


def parse_sockaddr(data: bytes) -> tuple[int, int] | None:
    """``(port, address)`` of a sockaddr info item, ``None`` when malformed."""
    if len(data) != 16:
        return None
    family, port, address = struct.unpack_from(">hHI", data)
    return (port, address) if family == 2 else None


# -- the side that answers CIP -------------------------------------------------------------
@dataclass(slots=True)
class Peer:
    """Who sent a request: the TCP connection's session and addresses."""

    session: int
    address: tuple[str, int]
    local: tuple[str, int]
    items: list[Item] = field(default_factory=list)   # extra CPF items of the request


class Target(Protocol):
    """What the encapsulation layer needs from the CIP side (:mod:`.router`)."""

    def identity_item(self, local: tuple[str, int]) -> bytes:
        """The body of the ListIdentity CIP identity item."""

    def unconnected(self, request: bytes, peer: Peer) -> tuple[bytes, list[Item]]:
        """Answer an unconnected request: the reply and extra CPF items."""

    def connected(self, conn_id: int, data: bytes, peer: Peer) -> tuple[int, bytes] | None:
        """Answer a class 3 request; ``(T->O connection id, sequence + reply)``."""

    def session_closed(self, session: int) -> None:
        """Drop what the session owned (class 3 connections)."""


class Sessions:
    """Session handles of one server, shared by its TCP connections."""

    def __init__(self, limit: int = 64) -> None:
        self.limit = limit
        self._next = 0x1000
        self.active: set[int] = set()

    def open(self) -> int | None:
        if len(self.active) >= self.limit:
            return None
        self._next = (self._next * 1103515245 + 12345) & 0x7FFFFFFF or 1
        while self._next in self.active or self._next == 0:
            self._next = (self._next + 1) & 0x7FFFFFFF
        self.active.add(self._next)
        return self._next

    def close(self, handle: int) -> None:
        self.active.discard(handle)


def list_services_item() -> Item:
    return Item(ITEM_SERVICES, struct.pack("<HH", 1, SERVICE_CAPABILITIES)
                + b"Communications\x00\x00")


def answer_list(frame: Frame, target: Target, local: tuple[str, int]) -> bytes | None:
    """ListIdentity / ListServices / ListInterfaces: the reply, or ``None`` for others."""
    if frame.command == LIST_IDENTITY:
        item = Item(ITEM_IDENTITY, target.identity_item(local))
        return frame.reply(encode_cpf([item]))
    if frame.command == LIST_SERVICES:
        return frame.reply(encode_cpf([list_services_item()]))
    if frame.command == LIST_INTERFACES:
        return frame.reply(encode_cpf([]))
    return None


def answer_datagram(buf: bytes, target: Target, local: tuple[str, int]) -> bytes | None:
    """UDP 44818: the list commands only; anything else is dropped."""
    frame = decode_frame(buf)
    if frame is None or frame.options or frame.status:
        return None
    return answer_list(frame, target, local)


class Connection:
    """The encapsulation state of one TCP connection."""

    def __init__(self, target: Target, sessions: Sessions, address: tuple[str, int],
                 local: tuple[str, int]) -> None:
        self.target = target
        self.sessions = sessions
        self.address = address
        self.local = local
        self.session = 0
        self.closing = False

    def close(self) -> None:
        """The TCP connection is gone: its session and class 3 connections end."""
        if self.session:
            self.sessions.close(self.session)
            self.target.session_closed(self.session)
            self.session = 0
        self.closing = True

    def handle(self, frame: Frame) -> bytes | None:
        """The reply to ``frame`` (``None``: no reply); sets :attr:`closing` as needed."""
        if frame.options or frame.status:
            return None                       # 2-3.4/2-3.6: discarded
        listed = answer_list(frame, self.target, self.local)
        if listed is not None:
            return listed
        if frame.command == NOP:
            return None
        if frame.command == REGISTER_SESSION:
            return self._register(frame)
        if frame.command == UNREGISTER_SESSION:
            if frame.session == self.session and self.session:
                self.close()
            return None
        if frame.command in (SEND_RR_DATA, SEND_UNIT_DATA):
            if not self.session or frame.session != self.session:
                return frame.reply(status=INVALID_SESSION)
            return self._send_data(frame)
        return frame.reply(status=INVALID_COMMAND)

    def _register(self, frame: Frame) -> bytes:
        if len(frame.data) != 4:
            return frame.reply(frame.data, INVALID_LENGTH)
        version, options = struct.unpack("<HH", frame.data)
        if version != PROTOCOL_VERSION or options != 0:     # options "shall be zero"
            return frame.reply(struct.pack("<HH", PROTOCOL_VERSION, 0), UNSUPPORTED_PROTOCOL)
        if self.session:
            return frame.reply(frame.data, INCORRECT_DATA, session=self.session)
        handle = self.sessions.open()
        if handle is None:
            return frame.reply(frame.data, NO_MEMORY)
        self.session = handle
        return frame.reply(frame.data, session=handle)

    def _send_data(self, frame: Frame) -> bytes | None:
        """SendRRData / SendUnitData: interface handle, timeout, then a CPF."""
        if len(frame.data) < 6:
            return frame.reply(status=INVALID_LENGTH)
        try:
            items = parse_cpf(frame.data[6:])
        except CpfError:
            return frame.reply(status=INCORRECT_DATA)
        if struct.unpack_from("<I", frame.data)[0] != 0 or len(items) < 2:
            return frame.reply(status=INCORRECT_DATA)
        head = frame.data[:6]
        if frame.command == SEND_RR_DATA:
            return self._unconnected(frame, head, items)
        return self._connected(frame, head, items)

    def _unconnected(self, frame: Frame, head: bytes, items: list[Item]) -> bytes:
        address, data = items[0], items[1]
        if address.type_id != ITEM_NULL or address.data or data.type_id != ITEM_UNCONNECTED_DATA:
            return frame.reply(status=INCORRECT_DATA)
        peer = Peer(self.session, self.address, self.local, items[2:])
        reply, extra = self.target.unconnected(data.data, peer)
        out = [Item(ITEM_NULL), Item(ITEM_UNCONNECTED_DATA, reply), *extra]
        return frame.reply(head[:4] + b"\x00\x00" + encode_cpf(out))

    def _connected(self, frame: Frame, head: bytes, items: list[Item]) -> bytes | None:
        address, data = items[0], items[1]
        if (address.type_id != ITEM_CONNECTED_ADDRESS or len(address.data) != 4
                or data.type_id != ITEM_CONNECTED_DATA):
            return frame.reply(status=INCORRECT_DATA)
        conn_id = struct.unpack("<I", address.data)[0]
        peer = Peer(self.session, self.address, self.local, items[2:])
        answer = self.target.connected(conn_id, data.data, peer)
        if answer is None:
            return None     # no such class 3 connection: silently dropped (3-4.2)
        to_id, reply = answer
        out = [Item(ITEM_CONNECTED_ADDRESS, struct.pack("<I", to_id)),
               Item(ITEM_CONNECTED_DATA, reply)]
        return frame.reply(head[:4] + b"\x00\x00" + encode_cpf(out))
