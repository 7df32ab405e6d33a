"""Connection Manager requests: Forward_Open, Large_Forward_Open, Forward_Close (CIP Vol 1 3-5.5).

Pure decoding and checking.  :func:`parse_open` turns the request data into an
:class:`OpenRequest` and :func:`check_class1` / :func:`check_class3` hold it
against what the adapter offers (its identity and connection, from its
:class:`~.description.AdapterDescription`); a refusal is a
``CipError`` with general status 0x01 and the extended status of CIP Vol 1 table
3-5.33, whose data is the unsuccessful reply body (triad, remaining path size).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, replace

from . import messages as cip
from .description import ConnectionInfo, IdentityInfo
from .messages import CipError
from .objects import ASSEMBLY_CLASS, ROUTER_CLASS

# extended status (CIP Vol 1 table 3-5.33)
DUPLICATE = 0x0100
BAD_TRANSPORT = 0x0103
OWNERSHIP_CONFLICT = 0x0106
NOT_FOUND = 0x0107
BAD_NETWORK_PARAMETER = 0x0108
RPI_NOT_SUPPORTED = 0x0111
OUT_OF_CONNECTIONS = 0x0113
VENDOR_MISMATCH = 0x0114
DEVICE_TYPE_MISMATCH = 0x0115
REVISION_MISMATCH = 0x0116
BAD_OT_TYPE = 0x0123
BAD_TO_TYPE = 0x0124
BAD_CONFIG_SIZE = 0x0126
BAD_OT_SIZE = 0x0127
BAD_TO_SIZE = 0x0128
BAD_CONFIG_PATH = 0x0129
BAD_CONSUMING_PATH = 0x012A
BAD_PRODUCING_PATH = 0x012B
BAD_SEGMENT = 0x0315

NULL, MULTICAST, POINT_TO_POINT = 0, 1, 2
SEQUENCE_SIZE = 2       # class 1 and 3 16-bit sequence count
HEADER_SIZE = 4         # 32-bit run/idle header


@dataclass(frozen=True, slots=True)
class NetParams:
    """Network connection parameters (CIP Vol 1 3-5.5.1.1)."""

    size: int
    variable: bool
    priority: int
    type: int

    @classmethod
    def decode(cls, value: int, large: bool) -> NetParams:
        if large:
            return cls(value & 0xFFFF, bool(value >> 25 & 1), value >> 26 & 3, value >> 29 & 3)
        return cls(value & 0x1FF, bool(value >> 9 & 1), value >> 10 & 3, value >> 13 & 3)


@dataclass(frozen=True, slots=True)
class OpenRequest:
    """A decoded Forward_Open."""

    ot_id: int
    to_id: int
    serial: int
    vendor: int
    originator: int
    multiplier: int
    ot_rpi: int
    ot: NetParams
    to_rpi: int
    to: NetParams
    transport: int
    path: cip.Path
    large: bool

    @property
    def triad(self) -> tuple[int, int, int]:
        return (self.serial, self.vendor, self.originator)

    @property
    def transport_class(self) -> int:
        return self.transport & 0x0F

    @property
    def timeout_us(self) -> int:
        """The consumer's inactivity timeout: O->T RPI times 4·2^multiplier (3-5.5.1.4)."""
        return self.ot_rpi * (4 << min(self.multiplier, 7))

    def failure(self, extended: int, *more: int) -> CipError:
        body = struct.pack("<HHIBB", self.serial, self.vendor, self.originator, 0, 0)
        return CipError(cip.CONNECTION_FAILURE, (extended, *more), body)


_OPEN = struct.Struct("<BBIIHHIB3xI")


def parse_open(data: bytes, large: bool) -> OpenRequest:
    """Decode Forward_Open (``large=False``) or Large_Forward_Open request data."""
    word = "I" if large else "H"
    tail = struct.Struct(f"<{word}I{word}BB")
    if len(data) < _OPEN.size + tail.size:
        raise CipError(cip.NOT_ENOUGH_DATA)
    _pt, _ticks, ot_id, to_id, serial, vendor, orig, mult, ot_rpi = _OPEN.unpack_from(data)
    ot_p, to_rpi, to_p, transport, words = tail.unpack_from(data, _OPEN.size)
    start = _OPEN.size + tail.size
    raw = data[start:start + 2 * words]
    partial = OpenRequest(ot_id, to_id, serial, vendor, orig, mult, ot_rpi,
                          NetParams.decode(ot_p, large), to_rpi, NetParams.decode(to_p, large),
                          transport, cip.Path(), large)
    if len(raw) < 2 * words:
        raise CipError(cip.NOT_ENOUGH_DATA)
    if len(data) > start + 2 * words:
        raise CipError(cip.TOO_MUCH_DATA)
    try:
        path = cip.parse_path(raw)
    except CipError:
        raise partial.failure(BAD_SEGMENT) from None
    return replace(partial, path=path)


def parse_close(data: bytes) -> tuple[tuple[int, int, int], cip.Path]:
    """Forward_Close: the triad and the connection path."""
    if len(data) < 12:
        raise CipError(cip.NOT_ENOUGH_DATA)
    _pt, _ticks, serial, vendor, orig, words = struct.unpack_from("<BBHHIB", data)
    raw = data[12:12 + 2 * words]
    if len(raw) < 2 * words:
        raise CipError(cip.NOT_ENOUGH_DATA)
    try:
        path = cip.parse_path(raw)
    except CipError:
        path = cip.Path()
    return (serial, vendor, orig), path


def close_reply(triad: tuple[int, int, int]) -> bytes:
    return struct.pack("<HHIBB", *triad, 0, 0)


def close_failure(triad: tuple[int, int, int]) -> CipError:
    return CipError(cip.CONNECTION_FAILURE, (NOT_FOUND,), struct.pack("<HHIBB", *triad, 0, 0))


def open_reply(req: OpenRequest, ot_id: int, to_id: int, ot_api: int, to_api: int) -> bytes:
    return struct.pack("<IIHHIIIBB", ot_id, to_id, req.serial, req.vendor, req.originator,
                       ot_api, to_api, 0, 0)


def check_key(req: OpenRequest, ours: IdentityInfo) -> None:
    """The electronic key against identity ``ours``, zero fields as wildcards (CIP Vol 1
    C-1.4.2)."""
    key = req.path.key
    if key is None:
        return
    vendor, dev_type, product, major, minor = struct.unpack("<HHHBB", key)
    compat, major = bool(major & 0x80), major & 0x7F
    if (vendor and vendor != ours.vendor_id) or (product and product != ours.product_code):
        raise req.failure(VENDOR_MISMATCH)
    if dev_type and dev_type != ours.device_type:
        raise req.failure(DEVICE_TYPE_MISMATCH)
    if major and (major != ours.revision[0]
                  or (minor and (minor > ours.revision[1] if compat
                                 else minor != ours.revision[1]))):
        raise req.failure(REVISION_MISMATCH)


def check_class1(req: OpenRequest, ours: IdentityInfo, offer: ConnectionInfo) -> bool:
    """Check a class 1 exclusive-owner open against ``offer``; returns whether O->T
    carries the header."""
    check_key(req, ours)
    if req.transport not in (0x01, 0x81):
        raise req.failure(BAD_TRANSPORT)
    path = req.path
    if path.class_id != ASSEMBLY_CLASS:
        raise req.failure(BAD_CONSUMING_PATH)
    if path.instance not in (None, offer.config):
        raise req.failure(BAD_CONFIG_PATH)
    if path.data:
        raise req.failure(BAD_CONFIG_SIZE)
    if len(path.points) != 2 or path.points[0] != offer.output:
        raise req.failure(BAD_CONSUMING_PATH)
    if path.points[1] != offer.input:
        raise req.failure(BAD_PRODUCING_PATH)
    for rpi in (req.ot_rpi, req.to_rpi):
        if not offer.rpi_min_us <= rpi <= offer.rpi_max_us:
            raise req.failure(RPI_NOT_SUPPORTED)
    if req.ot.type != POINT_TO_POINT:
        raise req.failure(BAD_OT_TYPE)
    if req.to.type not in (POINT_TO_POINT, MULTICAST):
        raise req.failure(BAD_TO_TYPE)
    return _check_sizes(req, offer)


def _check_sizes(req: OpenRequest, offer: ConnectionInfo) -> bool:
    out_size = offer.output_size + SEQUENCE_SIZE
    if req.ot.size == out_size + HEADER_SIZE:
        header = True
    elif req.ot.size == out_size:
        header = False
    else:
        raise req.failure(BAD_OT_SIZE, out_size + HEADER_SIZE)
    if req.to.size != offer.input_size + SEQUENCE_SIZE:
        raise req.failure(BAD_TO_SIZE, offer.input_size + SEQUENCE_SIZE)
    return header


def check_class3(req: OpenRequest, ours: IdentityInfo) -> None:
    """A class 3 explicit connection to the Message Router (20 02 24 01)."""
    check_key(req, ours)
    if req.transport & 0x0F != 3 or not req.transport & 0x80:
        raise req.failure(BAD_TRANSPORT)
    if req.path.class_id != ROUTER_CLASS or req.path.instance not in (None, 1) \
            or req.path.points or req.path.data:
        raise req.failure(BAD_CONSUMING_PATH)
    if req.ot.type != POINT_TO_POINT:
        raise req.failure(BAD_OT_TYPE)
    if req.to.type != POINT_TO_POINT:
        raise req.failure(BAD_TO_TYPE)
    if req.ot_rpi == 0 or req.to_rpi == 0:
        raise req.failure(RPI_NOT_SUPPORTED)
    if req.ot.size < 8 or req.to.size < 8:
        raise req.failure(BAD_OT_SIZE if req.ot.size < 8 else BAD_TO_SIZE)
