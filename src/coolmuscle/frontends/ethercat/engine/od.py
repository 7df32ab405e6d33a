"""The object dictionary's types: data types, entries, objects and the table of a slave.

CoE's model of a device (ETG.1000.6 5.6; CiA 301 7.4): an object (:class:`Obj`, an index)
is a VAR, ARRAY or RECORD of entries (:class:`Entry`, a subindex), each of a basic
data type (:class:`DataType`, ETG.1000.6 table 64) with its access, PDO mappability,
default, range and availability.  :class:`Table` is one slave's objects in index order,
with the PDO assignment (1C12h/1C13h) and mapping objects read out of it.

The slave description (:mod:`.description`) carries a table; the live dictionary
(:mod:`.dictionary`), the SII image (:mod:`.sii`) and the ESI file (:mod:`.esi`) are all
produced from it, so they cannot disagree.  Nothing here names a device: the tables
themselves are the application's.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from functools import cached_property


@dataclass(frozen=True)
class DataType:
    """A CoE basic data type (ETG.1000.6 table 64)."""

    code: int
    name: str
    bits: int
    fmt: str = ""            # struct format; "" for strings

    def encode(self, value: int | str | bytes) -> bytes:
        if not self.fmt:
            return value.encode("latin-1") if isinstance(value, str) else bytes(value)
        return struct.pack("<" + self.fmt, value)

    def decode(self, data: bytes) -> int | str:
        if not self.fmt:
            return data.decode("latin-1")
        value: int = struct.unpack("<" + self.fmt, data)[0]
        return value

    @property
    def size(self) -> int:
        return (self.bits + 7) // 8


BOOL = DataType(0x0001, "BOOL", 1, "?")
INT8 = DataType(0x0002, "SINT", 8, "b")
INT16 = DataType(0x0003, "INT", 16, "h")
INT32 = DataType(0x0004, "DINT", 32, "i")
UINT8 = DataType(0x0005, "USINT", 8, "B")
UINT16 = DataType(0x0006, "UINT", 16, "H")
UINT32 = DataType(0x0007, "UDINT", 32, "I")
STRING = DataType(0x0009, "STRING", 0)

VAR, ARRAY, RECORD = 7, 8, 9


@dataclass(frozen=True)
class Entry:
    """One subindex."""

    sub: int
    name: str
    dtype: DataType
    access: str = "ro"                    # "ro", "rw", "wo"
    pdo: str = ""                         # "", "rx" (RxPDO mappable), "tx"
    default: int | str = 0
    low: int | None = None
    high: int | None = None
    available: bool = True
    max_len: int = 0                      # strings: the longest value in bytes

    @property
    def bits(self) -> int:
        if self.dtype is STRING:
            return 8 * max(self.max_len, len(str(self.default)))
        return self.dtype.bits


@dataclass(frozen=True)
class Obj:
    """One object (index) of the dictionary."""

    index: int
    name: str
    entries: tuple[Entry, ...]
    code: int = VAR
    section: str = ""                     # the section of the slave's manual that defines it
    available: bool = True
    axis: int = 0                         # 1..n for per-axis objects, 0 for the device

    def entry(self, sub: int) -> Entry | None:
        for e in self.entries:
            if e.sub == sub:
                return e
        return None

    @property
    def max_sub(self) -> int:
        return max(e.sub for e in self.entries)


def var(index: int, name: str, dtype: DataType, access: str = "ro", default: int | str = 0,
        *, pdo: str = "", available: bool = True, section: str = "",
        low: int | None = None, high: int | None = None, max_len: int = 0) -> Obj:
    """A VAR: one entry, subindex 0."""
    return Obj(index, name, (Entry(0, name, dtype, access, pdo, default, low, high, True,
                                   max_len),), VAR, section, available)


def record(index: int, name: str, subs: list[Entry], *, code: int = RECORD,
           section: str = "", available: bool = True,
           count_type: DataType = UINT8, count_access: str = "ro",
           count: int | None = None) -> Obj:
    """An ARRAY/RECORD with subindex 0 'Number of entries' = the highest available sub."""
    highest = max((e.sub for e in subs if e.available), default=0)
    n = Entry(0, "Number of entries", count_type, count_access,
              default=highest if count is None else count)
    return Obj(index, name, (n, *subs), code, section, available)


def mapping(index: int, name: str, mapped: list[tuple[int, int, int]], available: bool,
            section: str) -> Obj:
    """A PDO mapping object: one UINT32 per mapped (index, subindex, bits) (CiA 301 7.5.2.36)."""
    subs = [Entry(i + 1, f"Subindex {i + 1:03d}", UINT32, "ro",
                  default=(idx << 16) | (sub << 8) | bits, available=available)
            for i, (idx, sub, bits) in enumerate(mapped)]
    return record(index, name, subs, available=available, section=section)


@dataclass(frozen=True)
class Table:
    """One slave's objects, in index order."""

    objects: tuple[Obj, ...] = field(default_factory=tuple)

    @cached_property
    def by_index(self) -> dict[int, Obj]:
        return {o.index: o for o in self.objects}

    def get(self, index: int) -> Obj | None:
        return self.by_index.get(index)

    def available(self) -> list[Obj]:
        return [o for o in self.objects if o.available]

    def rx_pdos(self) -> list[Obj]:
        """The RxPDOs assigned to SM2 (1C12h), in order."""
        return self._assigned(0x1C12)

    def tx_pdos(self) -> list[Obj]:
        """The TxPDOs assigned to SM3 (1C13h), in order."""
        return self._assigned(0x1C13)

    def _assigned(self, index: int) -> list[Obj]:
        assign = self.get(index)
        assert assign is not None
        out = []
        for e in assign.entries[1:]:
            pdo = self.get(int(e.default))
            assert pdo is not None
            out.append(pdo)
        return out

    def pdo_entries(self, pdo: Obj) -> list[tuple[Obj, Entry]]:
        """The (object, entry) pairs a mapping object maps, in order."""
        out = []
        for e in pdo.entries[1:]:
            if not e.available:
                continue
            value = int(e.default)
            target = self.get(value >> 16)
            assert target is not None, hex(value)
            entry = target.entry((value >> 8) & 0xFF)
            assert entry is not None
            out.append((target, entry))
        return out

    def image_bytes(self, pdos: list[Obj]) -> int:
        """The bytes of a process image made of ``pdos``."""
        return sum(entry.bits for pdo in pdos for _o, entry in self.pdo_entries(pdo)) // 8
