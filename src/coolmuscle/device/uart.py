"""What a UART set to one baud rate reads of bytes sent at another (ch. 3 K20).

ch. 3 K20: "When changed, the host baud rate needs to be changed to match COOL MUSCLE's
changed baud rate."  A motor and a host at different rates do not see each other's
bytes; each reads what its own UART makes of the other's waveform.  This module
computes that, deterministically, for the host line's wire model
(:class:`~coolmuscle.device.hostline.HostLine` with pacing on; docs/fidelity.md
"Baud rate of the host").

The model (the frame of 5.6.1: 8 data bits, no parity, 1 stop bit):

* the sender puts each byte on the line as a 10-bit frame, start bit (0), the data
  bits least significant first, stop bit (1), frames back to back, the line idle (1)
  before and after the chunk;
* the receiver waits for the line to be low (a falling edge, or at once when the line
  is still low after a frame: it re-synchronises on it, as a 16550 does after a
  framing error), then samples the middle of each of its own bit cells: the start bit
  (high there: a false start, it waits again), 8 data bits and the stop bit;
* a stop bit read as 0 is a framing error: the byte reads as 0x00 (what a Linux port
  in raw mode delivers, termios(3) ``IGNPAR`` unset); after the stop bit's sample the
  receiver waits for the next start.

Time is counted in units of ``1 / (2 * sent * read)`` seconds, so every instant is an
integer: a sent bit lasts ``2 * read`` units, a read bit ``2 * sent``.
"""

from __future__ import annotations

__all__ = ["as_read_at"]

#: Bits of one frame: start, 8 data, stop (5.6.1).
FRAME_BITS = 10


def as_read_at(data: bytes, sent_baud: int, read_baud: int) -> bytes:
    """The bytes a UART at ``read_baud`` reads of ``data`` sent at ``sent_baud``.

    Equal rates give ``data`` back unchanged."""
    if sent_baud == read_baud or not data:
        return data
    if sent_baud <= 0 or read_baud <= 0:
        raise ValueError(f"baud rates must be positive, not {sent_baud} / {read_baud}")
    line = _Waveform(data, 2 * read_baud)
    read_bit = 2 * sent_baud
    half = sent_baud
    out = bytearray()
    ready = 0                      # the receiver waits for a start from this instant on
    while True:
        start = line.next_low(ready)
        if start is None:
            return bytes(out)
        if line.level(start + half):                  # high mid-start: a false start
            ready = start + half + 1
            continue
        value = 0
        for bit in range(8):
            value |= line.level(start + (bit + 1) * read_bit + half) << bit
        stop_at = start + (FRAME_BITS - 1) * read_bit + half
        out.append(value if line.level(stop_at) else 0)
        ready = stop_at + 1


class _Waveform:
    """The line level of a chunk sent as back-to-back frames, idle around it."""

    def __init__(self, data: bytes, bit_units: int) -> None:
        self._bits: list[int] = []
        for byte in data:
            self._bits.append(0)
            self._bits.extend((byte >> i) & 1 for i in range(8))
            self._bits.append(1)
        self._unit = bit_units

    def level(self, t: int) -> int:
        index = t // self._unit
        return self._bits[index] if 0 <= index < len(self._bits) else 1

    def next_low(self, t: int) -> int | None:
        """The first instant at or after ``t`` at which the line is low, or None."""
        index = max(0, t // self._unit)
        if index < len(self._bits) and self._bits[index] == 0 and t >= 0:
            return t
        for later in range(index + 1, len(self._bits)):
            if self._bits[later] == 0:
                return later * self._unit
        return None
