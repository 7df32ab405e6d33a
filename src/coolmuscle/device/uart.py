"""What a UART set to one baud rate and frame reads of bytes sent at another (ch. 3 K20).

ch. 3 K20: "When changed, the host baud rate needs to be changed to match COOL MUSCLE's
changed baud rate."  A motor and a host at different rates (or frames: ch. 3 K82, the
parity) do not see each other's bytes; each reads what its own UART makes of the
other's waveform.  This module computes that, deterministically, for the host line's
wire model (:class:`~coolmuscle.device.hostline.HostLine` with pacing on;
docs/fidelity.md "Baud rate of the host").

The model (the motor's frame, 5.6.1: 8 data bits, K82 parity, 1 stop bit; a host's
port may be set to another :class:`Frame`):

* the sender puts each byte on the line as a frame, start bit (0), the data bits least
  significant first, the parity bit if any, the stop bits (1; one and a half or two),
  frames back to back, the line idle (1) before and after the chunk;
* the receiver waits for the line to be low (a falling edge, or at once when the line
  is still low after a frame: it re-synchronises on it, as a 16550 does after a
  framing error), then samples the middle of each of its own bit cells: the start bit
  (high there: a false start, it waits again), its data bits, its parity bit if any,
  and the first stop bit;
* a stop bit read as 0 is a framing error, a parity bit that does not match the data a
  parity error: either way the byte reads as 0x00 (what a Linux port in raw mode
  delivers, termios(3) ``IGNPAR`` unset); after the stop bit's sample the receiver
  waits for the next start.  Fewer than 8 data bits read as the low bits of a byte.

Time is counted in units of ``1 / (2 * sent * read)`` seconds, so every instant is an
integer: a sent bit lasts ``2 * read`` units (a half bit, for one and a half stop bits,
``read``), a read bit ``2 * sent``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Frame", "as_read_at", "PARITIES"]

#: Bits of the motor's frame without parity: start, 8 data, stop (5.6.1).
FRAME_BITS = 10

#: The rates a host's port may be set to: 50 bit/s (the slowest standard rate) to
#: 12 Mbit/s (the fastest common USB UART, FTDI's FT232H).  A receiver far faster or
#: slower than the sender reads a byte of framing errors per few bit times, so what it
#: reads grows with the ratio: the bounds keep that finite (docs/fidelity.md).
MIN_HOST_BAUD = 50
MAX_HOST_BAUD = 12_000_000


def bounded_host_baud(baud: int) -> int:
    """``baud`` within :data:`MIN_HOST_BAUD` .. :data:`MAX_HOST_BAUD` (a port set
    outside reads as at the nearest bound: garbage either way)."""
    return min(max(baud, MIN_HOST_BAUD), MAX_HOST_BAUD)


#: The parities of a frame: none, even, odd, mark (always 1), space (always 0).
PARITIES = ("N", "E", "O", "M", "S")


@dataclass(frozen=True)
class Frame:
    """How a UART frames a byte: data bits (5 to 8), parity (:data:`PARITIES`), stop
    bits (1, 1.5 or 2).  The default is the motor's with K82 = 0 (5.6.1)."""

    data_bits: int = 8
    parity: str = "N"
    stop_bits: float = 1

    def __post_init__(self) -> None:
        if (self.data_bits not in (5, 6, 7, 8) or self.parity not in PARITIES
                or self.stop_bits not in (1, 1.5, 2)):
            raise ValueError(f"not a UART frame: {self}")

    @property
    def bits(self) -> float:
        """Bit times of one frame on the line (start, data, parity, stop)."""
        return 1 + self.data_bits + (self.parity != "N") + self.stop_bits

    def parity_bit(self, value: int) -> int:
        """The parity bit this frame sends after the data bits of ``value``."""
        ones = bin(value & ((1 << self.data_bits) - 1)).count("1")
        return {"E": ones & 1, "O": 1 - (ones & 1), "M": 1}.get(self.parity, 0)


#: The motor's frame with K82 = 0, and a host's port set the factory way.
PLAIN = Frame()


def as_read_at(data: bytes, sent_baud: int, read_baud: int, sent: Frame = PLAIN,
               read: Frame = PLAIN) -> bytes:
    """The bytes a UART at ``read_baud`` framing ``read`` reads of ``data`` sent at
    ``sent_baud`` framing ``sent``.

    Equal rates, data bits and parity give ``data`` back (its low data bits)."""
    if sent_baud == read_baud and (sent.data_bits, sent.parity) == (read.data_bits,
                                                                    read.parity):
        mask = (1 << read.data_bits) - 1
        return data if mask == 0xFF else bytes(byte & mask for byte in data)
    if sent_baud <= 0 or read_baud <= 0:
        raise ValueError(f"baud rates must be positive, not {sent_baud} / {read_baud}")
    if not data:
        return data
    line = _Waveform(data, sent, read_baud)
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
        for bit in range(read.data_bits):
            value |= line.level(start + (bit + 1) * read_bit + half) << bit
        cell = read.data_bits + 1
        good = True
        if read.parity != "N":
            good = line.level(start + cell * read_bit + half) == read.parity_bit(value)
            cell += 1
        stop_at = start + cell * read_bit + half
        out.append(value if good and line.level(stop_at) else 0)
        ready = stop_at + 1


class _Waveform:
    """The line level of a chunk sent as back-to-back frames, idle around it, in half
    bits (one and a half stop bits are three)."""

    def __init__(self, data: bytes, frame: Frame, read_baud: int) -> None:
        self._halves: list[int] = []
        stop_halves = int(2 * frame.stop_bits)
        for byte in data:
            bits = [0, *((byte >> i) & 1 for i in range(frame.data_bits))]
            if frame.parity != "N":
                bits.append(frame.parity_bit(byte))
            for bit in bits:
                self._halves += (bit, bit)
            self._halves += [1] * stop_halves
        self._unit = read_baud           # a half bit lasts ``read`` units

    def level(self, t: int) -> int:
        index = t // self._unit
        return self._halves[index] if 0 <= index < len(self._halves) else 1

    def next_low(self, t: int) -> int | None:
        """The first instant at or after ``t`` at which the line is low, or None."""
        index = max(0, t // self._unit)
        if index < len(self._halves) and self._halves[index] == 0 and t >= 0:
            return t
        for later in range(index + 1, len(self._halves)):
            if self._halves[later] == 0:
                return later * self._unit
        return None
