"""The FMMUs of the ESC: logical addresses to physical memory (ETG.1000.4, ESC datasheet
section II 0x0600-0x06FF).

Each FMMU maps a run of logical bits (start address, length in bytes, start bit, end
bit) onto physical bits (start address, start bit), for reading, writing or both.
:func:`decode` reads the enabled FMMUs out of the register image once, when the master
writes their registers, into :class:`Fmmu` values that hold the mapped bit range; a
logical datagram then costs what it overlaps, not what the FMMU spans (a bit-wise FMMU
of 65,535 bytes meets a 4-byte datagram in 4 bytes' worth of work).
:func:`copy_bits` moves a run of bits between two buffers at any bit offsets, whole
integers at a time.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

#: Bytes of one FMMU's registers, and the offset of its enable byte.
FMMU_SIZE = 16
_ENABLE = 12
_LAYOUT = struct.Struct("<IHBBHBB")     # logical start, length, start bit, end bit,
                                        # physical start, physical start bit, type
READ, WRITE = 0x01, 0x02


@dataclass(frozen=True, slots=True)
class Fmmu:
    """One enabled FMMU, as bit ranges: logical ``[lbit, lbit + nbits)`` onto physical
    bits from ``pbit``; ``aligned`` when it maps whole bytes (start bits 0, end bit 7)."""

    lstart: int
    length: int
    lbit: int
    nbits: int
    pstart: int
    pbit: int
    kind: int
    aligned: bool

    @property
    def reads(self) -> bool:
        return bool(self.kind & READ)

    @property
    def writes(self) -> bool:
        return bool(self.kind & WRITE)

    def overlap(self, addr: int, length: int) -> tuple[int, int]:
        """The mapped logical bits ``[lo, hi)`` inside a datagram at ``addr`` of ``length``
        bytes (``lo >= hi``: none)."""
        return max(addr * 8, self.lbit), min((addr + length) * 8, self.lbit + self.nbits)


def decode(mem: bytes | bytearray, base: int, count: int) -> tuple[Fmmu, ...]:
    """The enabled FMMUs among ``count`` register sets from ``base``, with a mapping that
    covers at least one bit (length 0, or an end bit before the start bit of a one-byte
    FMMU, map nothing)."""
    out = []
    for i in range(count):
        at = base + FMMU_SIZE * i
        if not mem[at + _ENABLE] & 0x01:
            continue
        lstart, length, lsb, leb, pstart, psb, kind = _LAYOUT.unpack_from(mem, at)
        lsb, leb, psb = lsb & 7, leb & 7, psb & 7
        nbits = (length - 1) * 8 + leb - lsb + 1
        if length == 0 or nbits <= 0 or not kind & (READ | WRITE):
            continue
        out.append(Fmmu(lstart, length, lstart * 8 + lsb, nbits, pstart, pstart * 8 + psb,
                        kind & 3, lsb == 0 and psb == 0 and leb == 7))
    return tuple(out)


def copy_bits(src: bytes | bytearray, src_bit: int, dst: bytearray, dst_bit: int,
              count: int) -> None:
    """Copy ``count`` bits of ``src`` from bit ``src_bit`` into ``dst`` from bit ``dst_bit``
    (LSB first in each byte, as EtherCAT numbers bits); other bits of ``dst`` keep their
    values.  Both ranges must lie inside their buffers."""
    if count <= 0:
        return
    first = src_bit // 8
    chunk = int.from_bytes(src[first:(src_bit + count - 1) // 8 + 1], "little")
    value = (chunk >> (src_bit % 8)) & ((1 << count) - 1)
    lo, hi = dst_bit // 8, (dst_bit + count - 1) // 8 + 1
    shift = dst_bit % 8
    mask = ((1 << count) - 1) << shift
    old = int.from_bytes(dst[lo:hi], "little")
    dst[lo:hi] = ((old & ~mask) | (value << shift)).to_bytes(hi - lo, "little")
