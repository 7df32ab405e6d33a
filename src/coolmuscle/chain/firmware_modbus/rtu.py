"""Modbus RTU framing and COM0 in Modbus mode (cml-users-guide.txt 5.6.1–5.6.3, 5.6.9).

This module owns:

* the CRC-16 of 5.6.3 (polynomial 0xA001 reflected, start 0xFFFF, table-driven) and
  RTU frames ``address, PDU, CRC low, CRC high``;
* the silent interval of 5.6.2 that ends a message: 8 byte times of 8 bits
  (64 bit times: the table's 6.66 ms at 9.6 kbps ... 0.27 ms at 230.4 kbps),
  measured in virtual time at the K20 baud rate;
* :class:`RtuSlaveLine`, the host line's mode hook: while ID1's K81 is not 0
  (ch. 3 K84 table) the bytes of COM0 are Modbus RTU frames for
  :class:`~coolmuscle.chain.firmware_modbus.slave.ModbusSlave`, text replies and reports are not
  sent, and nine ``F`` in a row escape to the RS-232 text line until K81 is
  written (5.6.9).

A frame with a bad CRC, shorter than 4 bytes or longer than 256 is dropped
silently.  No I/O here: the host line brings the bytes and sends the responses.
"""

from __future__ import annotations

import logging
from functools import partial
from typing import TYPE_CHECKING

from ...device.hostline import BAUD_RATES, byte_time_ns
from ...sim.kernel import NS_PER_S, PRIO_IO, Timer
from .faults import rtu_reply
from .slave import ModbusSlave

if TYPE_CHECKING:
    from ...device.api import Device

log = logging.getLogger(__name__)

#: Smallest frame: address, function, CRC (2).  Largest: 256 bytes (Modbus RTU).
MIN_FRAME = 4
MAX_FRAME = 256
#: Bytes kept of one garbage message (enough to find an escape typed with a line).
MAX_BUFFER = 4096

#: 5.6.9: "sending 'FFFFFFFF' (Sending F nine times continuously)".
ESCAPE_BYTE = 0x46
ESCAPE_COUNT = 9


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        value = byte
        for _ in range(8):
            value = (value >> 1) ^ 0xA001 if value & 1 else value >> 1
        table.append(value)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes) -> bytes:
    """The Modbus CRC-16 of ``data`` as sent on the wire (low byte first).

    Written here rather than taken from pymodbus, whose import pulls asyncio and
    sockets into the model (docs/architecture.md rule 1); pymodbus checks it as a peer.
    """
    value = 0xFFFF
    table = _CRC_TABLE
    for byte in data:
        value = (value >> 8) ^ table[(value ^ byte) & 0xFF]
    return bytes((value & 0xFF, value >> 8))


def rtu_frame(address: int, pdu: bytes) -> bytes:
    """``address`` + ``pdu`` + CRC (5.6.3)."""
    head = bytes((address & 0xFF,)) + pdu
    return head + crc16(head)


def split_rtu_frame(frame: bytes) -> tuple[int, bytes] | None:
    """``(address, pdu)`` of a frame with a good CRC, else ``None``."""
    if not MIN_FRAME <= len(frame) <= MAX_FRAME or crc16(frame[:-2]) != frame[-2:]:
        return None
    return frame[0], frame[1:-2]


def silent_interval_ns(baud: int) -> int:
    """5.6.2: the gap that ends a message, 8 byte times of 8 bits at ``baud``."""
    return (64 * NS_PER_S) // baud


def byte_baud(k: int) -> int:
    """Bits per second of a K20 / K65 value (ch. 3 K20)."""
    return BAUD_RATES.get(k, 38400)


class RtuSlaveLine:
    """COM0 speaking Modbus RTU while ID1's K81 is not 0 (see module docstring).

    Installed as :attr:`coolmuscle.device.hostline.HostLine.mode` by the chain.
    """

    def __init__(self, device: Device, slave: ModbusSlave) -> None:
        self.device = device
        self.slave = slave
        self.kernel = device.kernel
        self._buf = bytearray()
        self._last_rx = 0
        self._timer: Timer | None = None
        self._f_run = 0
        #: a reply a wire fault holds back holds the later ones too (the slave answers
        #: one request after the other)
        self._reply_free_at = 0
        self.escaped = False
        self.frames = 0
        self.bad_frames = 0
        self.failures = 0

    # -- mode -----------------------------------------------------------------
    def station(self) -> int:
        """ID1's K81: 0 means COM0 speaks RS-232 text (ch. 3 K84 table)."""
        if not self.slave.enabled:
            return 0
        return self.device.get_param(1, 81)

    def active(self) -> bool:
        """Whether COM0 is in Modbus mode now (K81 ≠ 0 and not escaped)."""
        return not self.escaped and self.station() != 0

    def k81_written(self) -> None:
        """K81 was written: the temporary RS-232 mode ends (5.6.9)."""
        self.escaped = False
        self._reset()

    def _reset(self) -> None:
        self._buf.clear()
        self._f_run = 0
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def gap_ns(self) -> int:
        """The silent interval at ID1's K20 baud rate (5.6.2)."""
        return silent_interval_ns(byte_baud(self.device.get_param(1, 20)))

    # -- bytes in -----------------------------------------------------------------
    def receive(self, data: bytes) -> None:
        """Bytes from the host, arrived at ``kernel.now`` (their last byte)."""
        room = MAX_BUFFER - len(self._buf)
        if room > 0:
            self._buf += data[:room]
        self._last_rx = self.kernel.now
        if self._timer is None:
            self._timer = self.kernel.schedule(self.gap_ns(), self._check_end,
                                               priority=PRIO_IO, name="modbus-rtu-gap")

    def _check_end(self) -> None:
        self._timer = None
        due = self._last_rx + self.gap_ns()
        if self.kernel.now < due:   # more bytes came: wait for silence again
            self._timer = self.kernel.schedule_at(due, self._check_end, priority=PRIO_IO,
                                                  name="modbus-rtu-gap")
            return
        frame = bytes(self._buf)
        self._buf.clear()
        if len(frame) <= MAX_FRAME:
            parsed = split_rtu_frame(frame)
            if parsed is not None:
                self._f_run = 0
                self.frames += 1
                self._serve(*parsed)
                return
        self.bad_frames += 1
        self._look_for_escape(frame)

    def _serve(self, address: int, pdu: bytes) -> None:
        try:
            reply = self.slave.handle(address, pdu)
        except Exception:  # a model failure costs this request only (no reply)
            self.failures += 1
            log.exception("modbus: the model failed on %s", pdu[:16].hex(" "))
            return
        if reply is None:
            return
        frame = rtu_frame(address, reply)
        faults = self.device.wire_faults
        now = self.kernel.now
        if not faults.live("modbus-rtu") and self._reply_free_at <= now:
            self.device.host_line.write(frame)
            return
        baud = byte_baud(self.device.get_param(1, 20))      # a character: 10 bits (5.6.1)
        out = rtu_reply(faults, frame, byte_time_ns(baud), rtu_frame)
        at = max(now + out.late, self._reply_free_at)        # replies go out in order
        for pause, piece in out.pieces:
            at += pause
            if at <= now:
                self.device.host_line.write(piece)
            else:
                self.kernel.schedule_at(at, partial(self.device.host_line.write, piece),
                                        priority=PRIO_IO, name="modbus-rtu fault")
        self._reply_free_at = at

    def _look_for_escape(self, frame: bytes) -> None:
        """5.6.9: nine F in a row (across dropped frames) leave Modbus mode for now."""
        for i, byte in enumerate(frame):
            self._f_run = self._f_run + 1 if byte == ESCAPE_BYTE else 0
            if self._f_run >= ESCAPE_COUNT:
                self._escape(frame[i + 1:])
                return

    def _escape(self, rest: bytes) -> None:
        log.info("modbus: COM0 escaped to RS-232 text until K81 is written (5.6.9)")
        self._reset()
        self.escaped = True
        if rest:
            self.device.host_line.receive_text(rest)
