"""CIP messages: request paths (EPATH), service requests and replies, general status.

Sans-IO and pure: bytes in, dataclasses out, and back.  Every refusal is a
:class:`CipError` carrying the CIP general status (and extended status words, as
the Connection Manager uses them); it is raised deep inside and encoded once, by
:func:`encode_error`, at the Message Router (CIP Vol 1 ch. 2 and appendix B).

Only the segment types an adapter of this kind meets are decoded: logical class,
instance, attribute and connection point (8 and 16 bit), the electronic key
(0x34), port segments (routing, which this single-node adapter ignores) and the
simple data segment (0x80) of a Forward_Open.  Anything else is
``PATH_SEGMENT_ERROR``.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

# -- general status codes (CIP Vol 1 appendix B-1) ----------------------------------
SUCCESS = 0x00
CONNECTION_FAILURE = 0x01
RESOURCE_UNAVAILABLE = 0x02
PATH_SEGMENT_ERROR = 0x04
PATH_DESTINATION_UNKNOWN = 0x05
SERVICE_NOT_SUPPORTED = 0x08
INVALID_ATTRIBUTE_VALUE = 0x09
ALREADY_IN_STATE = 0x0B
OBJECT_STATE_CONFLICT = 0x0C
ATTRIBUTE_NOT_SETTABLE = 0x0E
DEVICE_STATE_CONFLICT = 0x10
REPLY_TOO_LARGE = 0x11
NOT_ENOUGH_DATA = 0x13
ATTRIBUTE_NOT_SUPPORTED = 0x14
TOO_MUCH_DATA = 0x15
OBJECT_DOES_NOT_EXIST = 0x16
INVALID_PARAMETER = 0x20
PATH_SIZE_INVALID = 0x26

# -- services (CIP Vol 1 appendix A) -------------------------------------------------
GET_ATTRIBUTES_ALL = 0x01
RESET = 0x05
GET_ATTRIBUTE_SINGLE = 0x0E
SET_ATTRIBUTE_SINGLE = 0x10
FORWARD_CLOSE = 0x4E
UNCONNECTED_SEND = 0x52
FORWARD_OPEN = 0x54
LARGE_FORWARD_OPEN = 0x5B
REPLY_BIT = 0x80


class CipError(Exception):
    """A refusal with its CIP general status and optional extended status words."""

    def __init__(self, status: int, extended: tuple[int, ...] = (), data: bytes = b"") -> None:
        super().__init__(f"CIP status 0x{status:02X} {tuple(hex(x) for x in extended)}")
        self.status = status
        self.extended = extended
        self.data = data


@dataclass(frozen=True, slots=True)
class Path:
    """A decoded request or connection path (CIP Vol 1 appendix C)."""

    class_id: int | None = None
    instance: int | None = None
    attribute: int | None = None
    points: tuple[int, ...] = ()      # connection points, in path order
    key: bytes | None = None          # electronic key body (8 bytes)
    data: bytes | None = None         # simple data segment
    ports: int = 0                    # port segments met (routing, ignored)


@dataclass(frozen=True, slots=True)
class Request:
    """One Message Router request: service, path and request data."""

    service: int
    path: Path
    data: bytes
    raw_path: bytes = b""


@dataclass(slots=True)
class _PathBuilder:
    class_id: int | None = None
    instance: int | None = None
    attribute: int | None = None
    points: list[int] = field(default_factory=list)
    key: bytes | None = None
    data: bytes | None = None
    ports: int = 0


def _take(buf: bytes, pos: int, n: int) -> bytes:
    if pos + n > len(buf):
        raise CipError(PATH_SEGMENT_ERROR)
    return buf[pos:pos + n]


def _logical(buf: bytes, pos: int, seg: int, out: _PathBuilder) -> int:
    """One logical segment (0x20-0x3F); returns the new position."""
    kind, fmt = (seg >> 2) & 0x07, seg & 0x03
    if seg == 0x34:                  # electronic key: format 4, 8 bytes of key data
        body = _take(buf, pos + 1, 9)
        if body[0] != 0x04:
            raise CipError(PATH_SEGMENT_ERROR)
        out.key = body[1:]
        return pos + 10
    if fmt == 0:
        value, pos = _take(buf, pos + 1, 1)[0], pos + 2
    elif fmt == 1:
        value, pos = struct.unpack_from("<H", _take(buf, pos + 2, 2))[0], pos + 4
    else:
        raise CipError(PATH_SEGMENT_ERROR)
    if kind == 0:
        out.class_id = value
    elif kind == 1:
        out.instance = value
    elif kind == 3:
        out.points.append(value)
    elif kind == 4:
        out.attribute = value
    else:
        raise CipError(PATH_SEGMENT_ERROR)
    return pos


def _port(buf: bytes, pos: int, seg: int, out: _PathBuilder) -> int:
    """A port segment (0x00-0x1F): skipped, this adapter routes nowhere."""
    out.ports += 1
    wide_port = (seg & 0x0F) == 0x0F
    extra = 2 if wide_port else 0
    if seg & 0x10:                      # extended link address: size byte, padded
        size = _take(buf, pos + 1, 1)[0]
        n = 2 + extra + size
        return pos + n + (n & 1)
    return pos + 2 + extra


def parse_path(buf: bytes) -> Path:
    """Decode a padded EPATH; raises ``CipError(PATH_SEGMENT_ERROR)`` on anything odd."""
    out, pos = _PathBuilder(), 0
    while pos < len(buf):
        seg = buf[pos]
        if 0x20 <= seg <= 0x3F:
            pos = _logical(buf, pos, seg, out)
        elif seg < 0x20:
            pos = _port(buf, pos, seg, out)
        elif seg == 0x80:
            words = _take(buf, pos + 1, 1)[0]
            out.data = _take(buf, pos + 2, 2 * words)
            pos += 2 + 2 * words
        else:
            raise CipError(PATH_SEGMENT_ERROR)
    if pos != len(buf):
        raise CipError(PATH_SIZE_INVALID)
    return Path(out.class_id, out.instance, out.attribute, tuple(out.points), out.key,
                out.data, out.ports)


def encode_path(class_id: int, instance: int | None = None,
                attribute: int | None = None) -> bytes:
    """A padded logical EPATH (8-bit segments where the value fits)."""
    out = bytearray()
    for kind, value in ((0x20, class_id), (0x24, instance), (0x30, attribute)):
        if value is None:
            continue
        if value <= 0xFF:
            out += bytes((kind, value))
        else:
            out += bytes((kind | 1, 0)) + struct.pack("<H", value)
    return bytes(out)


def parse_request(buf: bytes) -> Request:
    """Service, path size (words), path, data (CIP Vol 1 2-4.1)."""
    if len(buf) < 2:
        raise CipError(NOT_ENOUGH_DATA)
    service, words = buf[0], buf[1]
    end = 2 + 2 * words
    if end > len(buf):
        raise CipError(PATH_SIZE_INVALID)
    raw = bytes(buf[2:end])
    return Request(service, parse_path(raw), bytes(buf[end:]), raw)


def encode_reply(service: int, status: int = SUCCESS, data: bytes = b"",
                 extended: tuple[int, ...] = ()) -> bytes:
    """Reply service, reserved, general status, extended size (words), extended, data."""
    head = bytes((service | REPLY_BIT, 0, status, len(extended)))
    return head + b"".join(struct.pack("<H", w & 0xFFFF) for w in extended) + data


def encode_error(service: int, error: CipError) -> bytes:
    """The reply that carries ``error`` for a request of ``service``."""
    return encode_reply(service, error.status, error.data, error.extended)


def short_string(text: str) -> bytes:
    """CIP SHORT_STRING: length byte then ASCII."""
    raw = text.encode("ascii", "replace")[:255]
    return bytes((len(raw),)) + raw


def cip_string(text: str) -> bytes:
    """CIP STRING: UINT length then ASCII, padded to an even count (TCP/IP object)."""
    raw = text.encode("ascii", "replace")
    return struct.pack("<H", len(raw)) + raw + (b"\x00" if len(raw) & 1 else b"")
