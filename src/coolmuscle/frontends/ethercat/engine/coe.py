"""CoE: the SDO server and SDO information service (ETG.1000.6 5.6).

Sans-IO: :meth:`CoeServer.handle` takes one CoE payload (the mailbox data after the
mailbox header) and returns the CoE payloads to send back, in order.  Upload and
download, expedited, normal and segmented, complete access, abort; SDO
information: object list, object description, entry description (fragmented when
a list does not fit one mailbox).  Every refusal is an SDO abort code raised as
:class:`~.dictionary.SdoAbort` and encoded here, once.  Emergency messages are not
sent (no emergency service is offered).
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass

from .dictionary import (
    BAD_COMMAND,
    GENERAL,
    LENGTH_MISMATCH,
    NO_OBJECT,
    NO_SUBINDEX,
    OUT_OF_MEMORY,
    TOGGLE,
    Dictionary,
    SdoAbort,
)
from .od import ARRAY, RECORD, STRING, VAR, Entry

log = logging.getLogger(__name__)

SDO_REQUEST, SDO_RESPONSE, SDO_INFO = 2, 3, 8
#: The longest value a download may announce (more is refused with 05040005h).
MAX_TRANSFER = 4096
_MBX_HEADER = 6

# SDO information opcodes (ETG.1000.6 table 43).
OD_LIST_REQ, OD_LIST_RESP, OBJ_DESC_REQ, OBJ_DESC_RESP = 1, 2, 3, 4
ENTRY_DESC_REQ, ENTRY_DESC_RESP, INFO_ERROR = 5, 6, 7


@dataclass
class _Transfer:
    index: int
    sub: int
    complete: bool
    data: bytearray
    size: int
    toggle: int = 0
    upload: bool = True


def coe_header(service: int, number: int = 0) -> bytes:
    return struct.pack("<H", (number & 0x1FF) | (service & 0x0F) << 12)


def access_bits(entry: Entry) -> int:
    """ETG.1000.6 object access: read/write per state, PDO mappability."""
    bits = {"ro": 0x0007, "rw": 0x003F, "wo": 0x0038}[entry.access]
    if entry.pdo == "rx":
        bits |= 0x0040
    elif entry.pdo == "tx":
        bits |= 0x0080
    return bits


class CoeServer:
    """SDO server over one :class:`Dictionary`, for a mailbox of ``mailbox_size`` bytes."""

    def __init__(self, dictionary: Dictionary, mailbox_size: int) -> None:
        self.od = dictionary
        self.capacity = mailbox_size - _MBX_HEADER        # CoE payload bytes per mailbox
        self._transfer: _Transfer | None = None

    def handle(self, payload: bytes) -> list[bytes]:
        """Serve one CoE payload; returns the CoE payloads of the answer."""
        if len(payload) < 2:
            return []
        service = payload[1] >> 4
        if service == SDO_REQUEST:
            answer = self._sdo(payload[2:])
            return [answer] if answer else []
        if service == SDO_INFO:
            return self._info(payload[2:])
        raise UnsupportedService(service)

    # -- SDO ------------------------------------------------------------------
    def _sdo(self, sdo: bytes) -> bytes:
        sdo = sdo.ljust(8, b"\x00")
        cmd = sdo[0]
        index, sub = struct.unpack_from("<HB", sdo, 1)
        try:
            answer = self._command(cmd, index, sub, sdo)
            return coe_header(SDO_RESPONSE) + answer if answer else b""
        except SdoAbort as abort:
            self._transfer = None      # an abort travels as an SDO request (ETG.1000.6 5.6.2.7)
            return coe_header(SDO_REQUEST) + _abort(index, sub, abort.code)
        except Exception:           # a bug must not crash the slave: answer 08000000h
            log.exception("SDO %04Xh.%d failed", index, sub)
            self._transfer = None
            return coe_header(SDO_REQUEST) + _abort(index, sub, GENERAL)

    def _command(self, cmd: int, index: int, sub: int, sdo: bytes) -> bytes:
        ccs = cmd >> 5
        if ccs == 1:
            return self._download(cmd, index, sub, sdo)
        if ccs == 2:
            return self._upload(cmd, index, sub)
        if ccs == 0:
            return self._download_segment(cmd, sdo)
        if ccs == 3:
            return self._upload_segment(cmd)
        if ccs == 4:
            self._transfer = None
            return b""
        raise SdoAbort(BAD_COMMAND)

    def _upload(self, cmd: int, index: int, sub: int) -> bytes:
        self._transfer = None
        complete = bool(cmd & 0x10)
        data = self.od.read_complete(index, sub) if complete else self.od.read(index, sub)
        flags = cmd & 0x10
        if len(data) <= 4 and not self._is_string(index, sub, complete):
            return struct.pack("<BHB", 0x43 | flags | (4 - len(data)) << 2, index, sub) \
                + data.ljust(4, b"\x00")
        room = self.capacity - 2 - 8
        head = struct.pack("<BHBI", 0x41 | flags, index, sub, len(data))
        if len(data) <= room:
            return head + data
        self._transfer = _Transfer(index, sub, complete, bytearray(data[room:]), len(data))
        return head + data[:room]

    def _is_string(self, index: int, sub: int, complete: bool) -> bool:
        if complete:
            return False
        try:
            _obj, entry = self.od.lookup(index, sub)
        except SdoAbort:
            return False
        return entry.dtype is STRING

    def _upload_segment(self, cmd: int) -> bytes:
        t = self._transfer
        if t is None or not t.upload:
            raise SdoAbort(BAD_COMMAND)
        toggle = cmd & 0x10
        if toggle != t.toggle:
            raise SdoAbort(TOGGLE)
        room = self.capacity - 2 - 1
        chunk, rest = bytes(t.data[:room]), t.data[room:]
        last = not rest
        t.data, t.toggle = rest, t.toggle ^ 0x10
        if last:
            self._transfer = None
        size_bits = (7 - len(chunk)) << 1 if len(chunk) < 7 else 0
        return bytes([toggle | size_bits | (1 if last else 0)]) + chunk.ljust(7, b"\x00")

    def _download(self, cmd: int, index: int, sub: int, sdo: bytes) -> bytes:
        self._transfer = None
        complete = bool(cmd & 0x10)
        if cmd & 0x02:                                      # expedited
            sized = bool(cmd & 0x01)
            data = sdo[4:8 - ((cmd >> 2) & 0x03)] if sized else sdo[4:8]
            self._store(index, sub, complete, data, sized)
        else:
            size, = struct.unpack_from("<I", sdo, 4)
            data = sdo[8:]
            if size > MAX_TRANSFER:
                raise SdoAbort(OUT_OF_MEMORY)
            if size <= len(data):
                self._store(index, sub, complete, data[:size], True)
            else:
                self._transfer = _Transfer(index, sub, complete, bytearray(data), size,
                                           upload=False)
        return struct.pack("<BHBI", 0x60, index, sub, 0)

    def _download_segment(self, cmd: int, sdo: bytes) -> bytes:
        t = self._transfer
        if t is None or t.upload:
            raise SdoAbort(BAD_COMMAND)
        toggle = cmd & 0x10
        if toggle != t.toggle:
            raise SdoAbort(TOGGLE)
        seg = sdo[1:] if len(sdo) > 8 else sdo[1:8 - ((cmd >> 1) & 0x07)]
        t.data += seg
        t.toggle ^= 0x10
        if cmd & 0x01:                                      # last segment
            self._transfer = None
            if len(t.data) < t.size:
                raise SdoAbort(LENGTH_MISMATCH)
            self._store(t.index, t.sub, t.complete, bytes(t.data[:t.size]), True)
        elif len(t.data) > t.size:
            raise SdoAbort(LENGTH_MISMATCH)
        return bytes([0x20 | toggle]) + bytes(7)

    def _store(self, index: int, sub: int, complete: bool, data: bytes, sized: bool) -> None:
        if complete:
            self.od.write_complete(index, sub, data)
        else:
            self.od.write(index, sub, data, sized=sized)

    # -- SDO information ---------------------------------------------------------------
    def _info(self, body: bytes) -> list[bytes]:
        if len(body) < 4:
            return [self._info_error(BAD_COMMAND)]
        opcode = body[0] & 0x7F
        data = body[4:]
        try:
            if opcode == OD_LIST_REQ:
                return self._od_list(data)
            if opcode == OBJ_DESC_REQ:
                return self._fragments(OBJ_DESC_RESP, self._object_description(data))
            if opcode == ENTRY_DESC_REQ:
                return self._fragments(ENTRY_DESC_RESP, self._entry_description(data))
            raise SdoAbort(BAD_COMMAND)
        except SdoAbort as abort:
            return [self._info_error(abort.code)]
        except Exception:
            log.exception("SDO information request failed")
            return [self._info_error(GENERAL)]

    def _info_error(self, code: int) -> bytes:
        return coe_header(SDO_INFO) + struct.pack("<BBHI", INFO_ERROR, 0, 0, code)

    def _od_list(self, data: bytes) -> list[bytes]:
        if len(data) < 2:
            raise SdoAbort(BAD_COMMAND)
        kind, = struct.unpack_from("<H", data)
        objects = self.od.objects()
        rx = [o.index for o in objects if any(e.pdo == "rx" for e in o.entries)]
        tx = [o.index for o in objects if any(e.pdo == "tx" for e in o.entries)]
        lists = {1: [o.index for o in objects], 2: rx, 3: tx, 4: [], 5: []}
        if kind == 0:
            counts = [len(lists[k]) for k in range(1, 6)]
            return self._fragments(OD_LIST_RESP, struct.pack("<6H", 0, *counts))
        if kind not in lists:
            raise SdoAbort(BAD_COMMAND)
        body = struct.pack("<H", kind) + b"".join(struct.pack("<H", i) for i in lists[kind])
        return self._fragments(OD_LIST_RESP, body)

    def _object_description(self, data: bytes) -> bytes:
        if len(data) < 2:
            raise SdoAbort(BAD_COMMAND)
        index, = struct.unpack_from("<H", data)
        obj = {o.index: o for o in self.od.objects()}.get(index)
        if obj is None:
            raise SdoAbort(NO_OBJECT)
        if obj.code == VAR:
            dtype = obj.entries[0].dtype.code
        elif obj.code == ARRAY:
            dtype = obj.entries[1].dtype.code
        else:
            dtype = 0x002A if obj.code == RECORD else 0
        max_sub = max(e.sub for e in obj.entries if e.available)
        return struct.pack("<HHBB", index, dtype, max_sub, obj.code) + obj.name.encode("latin-1")

    def _entry_description(self, data: bytes) -> bytes:
        if len(data) < 4:
            raise SdoAbort(BAD_COMMAND)
        index, sub, _value_info = struct.unpack_from("<HBB", data)
        try:
            _obj, entry = self.od.lookup(index, sub)
        except SdoAbort as abort:
            raise SdoAbort(NO_SUBINDEX if abort.code == NO_SUBINDEX else NO_OBJECT) from None
        return struct.pack("<HBBHHH", index, sub, 0, entry.dtype.code, entry.bits,
                           access_bits(entry)) + entry.name.encode("latin-1")

    def _fragments(self, opcode: int, body: bytes) -> list[bytes]:
        """Split an information response over mailboxes (incomplete flag, fragments left)."""
        room = self.capacity - 2 - 4
        pieces = [body[i:i + room] for i in range(0, len(body), room)] or [b""]
        out = []
        for n, piece in enumerate(pieces):
            left = len(pieces) - 1 - n
            op = opcode | (0x80 if left else 0)
            out.append(coe_header(SDO_INFO) + struct.pack("<BBH", op, 0, left) + piece)
        return out


def _abort(index: int, sub: int, code: int) -> bytes:
    return struct.pack("<BHBI", 0x80, index, sub, code)


class UnsupportedService(Exception):
    """A CoE service the server does not offer (answered with a mailbox error)."""

    def __init__(self, service: int) -> None:
        super().__init__(f"CoE service {service} not supported")
        self.service = service
