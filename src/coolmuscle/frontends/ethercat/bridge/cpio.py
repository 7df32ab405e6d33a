"""CPIO mode bits (ethercat-bridge-users-guide.txt 7.1.1-7.1.3): pure functions.

Controlword ``C0*Fh``: bits 12-15 = 1100, bits 4-7 drive OUT1-OUT4, bits 0-3 the
CiA402 command.  Statusword: 1100, the CM status in bits 8-11 (Note1: bit 8
counter overflow, 9 over speed / regenerative voltage, 10 overload, 11
in-position, 1111 serial communication error: the low four bits of Ux),
INPUT1-4 in bits 4-7, the CiA402 lower four bits in bits 0-3.  CM1 has OUT2 only
and reports INPUT2-4 (its OUT1 and INPUT1 carry the serial line, 2.5.2).
"""

from __future__ import annotations

from typing import Final

TAG: Final = 0xC000
SERIAL_ERROR: Final = 0xF


def is_cpio_word(controlword: int) -> bool:
    return controlword & 0xF000 == TAG


def outputs_of(controlword: int, firmware: str) -> int:
    """The OUT1-OUT4 word (bit0 = OUT1) a CPIO controlword asks for."""
    word = (controlword >> 4) & 0x0F
    return word & 0b0010 if firmware == "cm1" else word


def output_mask(firmware: str) -> int:
    """The outputs the bridge may set (6.5.2, 7.1.2 Note1)."""
    return 0b0010 if firmware == "cm1" else 0b1111


def input_mask(firmware: str) -> int:
    """60FDh bits (6.5.1): CM1 In2-In4 (bits 1-3), CM2 In1-In6 (bits 0-5)."""
    return 0b001110 if firmware == "cm1" else 0b111111


def statusword(cia402_word: int, ux: int, inputs: int, firmware: str, link_ok: bool = True) -> int:
    """The CPIO statusword of 7.1.3."""
    cm = (ux & 0x0F) if link_ok else SERIAL_ERROR
    ins = inputs & (0b1110 if firmware == "cm1" else 0b1111)
    return TAG | cm << 8 | ins << 4 | (cia402_word & 0x0F)


def output_commands(motor: int, old: int, new: int, mask: int) -> str:
    """The CML line that changes OUT bits ``old`` -> ``new`` (``O#.n`` on, ``F#.n`` off)."""
    parts = []
    for bit in range(4):
        b = 1 << bit
        if mask & b and (old ^ new) & b:
            parts.append(f"{'O' if new & b else 'F'}{bit + 1}.{motor}")
    return ",".join(parts)
