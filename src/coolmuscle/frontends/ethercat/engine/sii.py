"""The SII EEPROM image of a slave (ETG.1000.6 5.4, ETG.2010), from its description.

Words 0-7: the ESC configuration area (word 0 the PDI control) with its CRC-8
(polynomial 0x07, initial 0xFF) in word 7; words 8-15 the identity (1018h); 0x14-0x1C
the bootstrap and standard mailbox (SM0 out, SM1 in) and the mailbox protocols (CoE);
0x3E the EEPROM size.  Categories from word 0x40: strings (10), general (30, with the
CoE details), FMMU (40: outputs, inputs, mailbox status), SyncManager (41), RxPDO (51)
and TxPDO (50) from the PDO assignment of the description's table, end (0xFFFF).
:func:`parse` reads an image back (tests compare it with the ESI and the dictionary).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from .description import SlaveDescription
from .od import Obj, Table

EEPROM_BYTES = 2048
CAT_STRINGS, CAT_GENERAL, CAT_FMMU, CAT_SM, CAT_TXPDO, CAT_RXPDO, CAT_END = \
    10, 30, 40, 41, 50, 51, 0xFFFF

#: CoE details (general category): SDO, SDO information, complete access (ETG.2010).
COE_DETAILS = 0x01 | 0x02 | 0x20
MBX_COE = 0x0004
#: FMMU usage (category 40): outputs, inputs, mailbox status; 0xFF pads the category.
FMMU_USAGE = bytes([1, 2, 3, 0xFF])
#: The profile whose channel count goes into the general category (DS402 channels).
DS402 = 402


def crc8(data: bytes) -> int:
    """CRC of the ESC configuration area (x^8 + x^2 + x + 1, initial 0xFF)."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


class _Strings:
    def __init__(self) -> None:
        self.items: list[str] = []

    def add(self, text: str) -> int:
        if text not in self.items:
            self.items.append(text)
        return self.items.index(text) + 1

    def encode(self) -> bytes:
        out = bytearray([len(self.items)])
        for s in self.items:
            raw = s.encode("latin-1")[:255]
            out += bytes([len(raw)]) + raw
        return bytes(out)


def _category(kind: int, data: bytes) -> bytes:
    if len(data) % 2:
        data += b"\x00"
    return struct.pack("<HH", kind, len(data) // 2) + data


def _pdo_category(table: Table, pdos: list[Obj], sm: int, strings: _Strings) -> bytes:
    out = bytearray()
    for pdo in pdos:
        entries = table.pdo_entries(pdo)
        out += struct.pack("<HBBBBH", pdo.index, len(entries), sm, 0, strings.add(pdo.name),
                           0x0011)        # flags: mandatory, fixed content
        for obj, entry in entries:
            name = strings.add(obj.name if obj.entries[0] is entry else entry.name)
            out += struct.pack("<HBBBBH", obj.index, entry.sub, name, entry.dtype.code,
                               entry.bits, 0)
    return bytes(out)


def build_sii(slave: SlaveDescription) -> bytes:
    """The EEPROM image (2 KiB, erased bytes 0xFF) of the slave ``slave`` describes."""
    ident, table = slave.identity, slave.table
    mbx_out, mbx_in = slave.mailbox_out, slave.mailbox_in
    head = bytearray(128)
    struct.pack_into("<HHHH", head, 0, slave.pdi_control, 0x0000, 0x0000, 0x0000)
    struct.pack_into("<H", head, 8, 0x0000)                               # station alias
    head[14] = crc8(bytes(head[:14]))
    struct.pack_into("<IIII", head, 16, ident.vendor_id, ident.product_code, ident.revision,
                     ident.serial)
    struct.pack_into("<HHHH", head, 0x14 * 2, mbx_out.start, mbx_out.size,
                     mbx_in.start, mbx_in.size)                           # bootstrap = std
    struct.pack_into("<HHHHH", head, 0x18 * 2, mbx_out.start, mbx_out.size,
                     mbx_in.start, mbx_in.size, MBX_COE)
    struct.pack_into("<HH", head, 0x3E * 2, EEPROM_BYTES * 8 // 1024 - 1, 1)

    strings = _Strings()
    name = strings.add(slave.names.device)
    group = strings.add(slave.names.group)
    order = strings.add(slave.names.order)
    general = bytearray(32)
    general[0], general[2], general[3] = group, order, name
    general[5] = COE_DETAILS
    general[9] = slave.channels if slave.profile == DS402 else 0      # DS402 channels
    general[11] = 0x00                      # flags
    rx = _pdo_category(table, table.rx_pdos(), 2, strings)
    tx = _pdo_category(table, table.tx_pdos(), 3, strings)
    sms = b"".join(struct.pack("<HHBBBB", start, length, control, 0, 1, kind)
                   for kind, (start, length, control) in enumerate(slave.sync_managers(), 1))
    body = (_category(CAT_STRINGS, strings.encode()) + _category(CAT_GENERAL, bytes(general))
            + _category(CAT_FMMU, FMMU_USAGE) + _category(CAT_SM, sms)
            + _category(CAT_TXPDO, tx) + _category(CAT_RXPDO, rx)
            + struct.pack("<H", CAT_END))
    image = bytes(head) + body
    if len(image) > EEPROM_BYTES:
        raise ValueError("SII image larger than the EEPROM")
    return image.ljust(EEPROM_BYTES, b"\xff")


@dataclass
class SiiInfo:
    """What :func:`parse` reads back from an image."""

    vendor: int = 0
    product: int = 0
    revision: int = 0
    serial: int = 0
    mailbox: tuple[int, int, int, int] = (0, 0, 0, 0)
    protocols: int = 0
    strings: list[str] = field(default_factory=list)
    name: str = ""
    coe_details: int = 0
    fmmu: list[int] = field(default_factory=list)
    sms: list[tuple[int, int, int, int, int]] = field(default_factory=list)
    rxpdo: list[tuple[int, list[tuple[int, int, int]]]] = field(default_factory=list)
    txpdo: list[tuple[int, list[tuple[int, int, int]]]] = field(default_factory=list)
    crc_ok: bool = False


def parse(image: bytes) -> SiiInfo:
    """Read the fields a master uses out of an SII image."""
    info = SiiInfo()
    info.crc_ok = crc8(image[:14]) == image[14]
    info.vendor, info.product, info.revision, info.serial = struct.unpack_from("<IIII", image, 16)
    info.mailbox = struct.unpack_from("<HHHH", image, 0x18 * 2)
    info.protocols, = struct.unpack_from("<H", image, 0x1C * 2)
    pos = 0x40 * 2
    while pos + 4 <= len(image):
        kind, words = struct.unpack_from("<HH", image, pos)
        if kind == CAT_END:
            break
        data = image[pos + 4:pos + 4 + 2 * words]
        pos += 4 + 2 * words
        if kind == CAT_STRINGS:
            at = 1
            for _ in range(data[0]):
                n = data[at]
                info.strings.append(data[at + 1:at + 1 + n].decode("latin-1"))
                at += 1 + n
        elif kind == CAT_GENERAL:
            info.name = info.strings[data[3] - 1] if data[3] else ""
            info.coe_details = data[5]
        elif kind == CAT_FMMU:
            info.fmmu = [b for b in data if b != 0xFF]
        elif kind == CAT_SM:
            info.sms = [struct.unpack_from("<HHBBBB", data, i)[:1] + struct.unpack_from(
                "<HHBBBB", data, i)[1:3] + struct.unpack_from("<HHBBBB", data, i)[4:6]
                for i in range(0, len(data) - 7, 8)]
        elif kind in (CAT_RXPDO, CAT_TXPDO):
            (info.rxpdo if kind == CAT_RXPDO else info.txpdo).extend(_parse_pdos(data))
    return info


def _parse_pdos(data: bytes) -> list[tuple[int, list[tuple[int, int, int]]]]:
    out = []
    at = 0
    while at + 8 <= len(data):
        index, n = struct.unpack_from("<HB", data, at)
        at += 8
        entries = []
        for _ in range(n):
            eidx, esub, _name, _dtype, bits = struct.unpack_from("<HBBBB", data, at)
            entries.append((eidx, esub, bits))
            at += 8
        out.append((index, entries))
    return out
