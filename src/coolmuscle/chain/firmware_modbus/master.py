"""COM1 as a Modbus RTU host: the I/O slave seen as "final motor ID + 1" (cml-users-guide.txt 5.6).

This module owns the Modbus messages the motor generates from CML commands
addressed to the slave device (5.6 "Modbus Slave Communication", 5.6.6 setting
example 3, 5.6.7 FC01/02/05/15) and how it reads the answers:

=================  ==========================================  ==================
CML                request (slave address 1)                    printed
=================  ==========================================  ==================
``?50.n``          FC01, 16 outputs from K80                    ``OUT.n=XXXX``
``?70.n``          FC02, 16 inputs from K79                     ``IN.n=XXXX``
``O#.n``/``F#.n``  FC05, output # at K80 + # - 1, FF00/0000     nothing
``O.n=X``          FC15, 16 outputs from K80, X in 2 bytes      nothing
=================  ==========================================  ==================

COM1 is the free port of the final motor, a Modbus host when that motor's K84 is 1
(ch. 3 K84 table).  The 16-bit words of FC01/02/15 are sent high byte first, or low
byte first when K85 sets COM1 to little endian (2 or 3).  One request is on the
wire at a time; the answer must come within :data:`RESPONSE_TIMEOUT_NS` of virtual
time.  No answer, a bad CRC or an exception response prints nothing (the command
goes unanswered, like one for an absent motor) and is counted.

No I/O here: a front end (``coolmuscle sim --com1``) or a test feeds the slave's
bytes to :meth:`Com1Port.feed` and writes what :meth:`Com1Port.add_listener` gives.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ...sim.kernel import NS_PER_MS, NS_PER_S, PRIO_IO, Timer
from .rtu import byte_baud, crc16, rtu_frame, silent_interval_ns
from .slave import supports_modbus

if TYPE_CHECKING:
    from ...device.api import Device

log = logging.getLogger(__name__)

#: 5.6.6 setting example 3: "Be sure to set the Modbus address of Device 1 (ID4) as 1."
SLAVE_ADDRESS = 1
#: 5.6.7: "The number of Read Registers is fixed to 16."
POINTS = 16
#: The manual gives no response timeout; 500 ms of virtual time (docs/fidelity.md).
RESPONSE_TIMEOUT_NS = 500 * NS_PER_MS

READ_COILS, READ_DISCRETE, WRITE_COIL, WRITE_COILS = 0x01, 0x02, 0x05, 0x0F

Emit = Callable[..., None]
ByteListener = Callable[[bytes], None]


@dataclass(frozen=True, slots=True)
class Request:
    """One message to the slave and what to do with its answer."""

    frame: bytes
    origin: str
    label: str = ""      # "IN" / "OUT" for reads; "" for writes

    @property
    def function(self) -> int:
        return self.frame[1]

    @property
    def response_length(self) -> int:
        """Bytes of the normal response: reads carry 2 data bytes (16 points)."""
        return 7 if self.label else 8


class Com1Port:
    """COM1 of the final motor as a Modbus host (see module docstring)."""

    def __init__(self, device: Device, emit: Emit) -> None:
        self.device = device
        self.kernel = device.kernel
        self._emit = emit
        self._listeners: list[ByteListener] = []
        self._queue: deque[Request] = deque()
        self._pending: Request | None = None
        self._buf = bytearray()
        self._last_rx = 0
        self._timeout: Timer | None = None
        self._free_at = 0
        self.sent = 0
        self.answered = 0
        self.timeouts = 0
        self.exceptions = 0
        self.errors = 0

    # -- configuration (the final motor's parameters) ----------------------------
    @property
    def final_motor(self) -> int:
        return max(self.device.motor_ids)

    @property
    def io_id(self) -> int:
        """The CML ID of the slave device: final motor ID + 1 (5.6.6 setting example 3)."""
        return self.final_motor + 1

    def enabled(self) -> bool:
        """K84 = 1 on the final motor: COM1 is a Modbus host (ch. 3 K84)."""
        return supports_modbus(self.device) and self.device.get_param(self.final_motor, 84) == 1

    def serves(self, motor_id: int) -> bool:
        """Whether a statement for ``motor_id`` goes to the slave device."""
        return motor_id == self.io_id and self.enabled()

    def baud(self) -> int:
        """K65 of the final motor (5.6 parameter table)."""
        return byte_baud(self.device.get_param(self.final_motor, 65))

    def parity(self) -> str:
        """K82 of the final motor: ``"N"``, ``"E"`` or ``"O"``."""
        return "NEO"[self.device.get_param(self.final_motor, 82) % 3]

    def little_endian(self) -> bool:
        """K85 2 or 3: COM1 little endian (ch. 3 K85 table)."""
        return self.device.get_param(self.final_motor, 85) in (2, 3)

    # -- requests from CML ----------------------------------------------------------
    def read_inputs(self, origin: str) -> bool:
        """``?70.n``: FC02, 16 inputs from K79 (5.6.7); ``False`` when K79 is -1."""
        start = self.device.get_param(self.final_motor, 79)
        if start < 0:
            return False
        self._submit(self._pdu(READ_DISCRETE, start, POINTS), origin, "IN")
        return True

    def read_outputs(self, origin: str) -> bool:
        """``?50.n``: FC01, 16 outputs from K80 (5.6.7)."""
        start = self.device.get_param(self.final_motor, 80)
        self._submit(self._pdu(READ_COILS, start, POINTS), origin, "OUT")
        return True

    def write_output(self, number: int, on: bool, origin: str) -> None:
        """``O#.n`` / ``F#.n``: FC05 at K80 + # - 1 (docs/fidelity.md "Modbus")."""
        start = self.device.get_param(self.final_motor, 80) + number - 1
        self._submit(self._pdu(WRITE_COIL, start, 0xFF00 if on else 0x0000), origin)

    def write_outputs(self, word: int, origin: str) -> None:
        """``O.n=X``: FC15, 16 outputs from K80, 2 data bytes (5.6.7)."""
        start = self.device.get_param(self.final_motor, 80)
        data = self._word_bytes(word)
        pdu = self._pdu(WRITE_COILS, start, POINTS) + bytes((len(data),)) + data
        self._submit(pdu, origin)

    @staticmethod
    def _pdu(function: int, first: int, second: int) -> bytes:
        return bytes((function,)) + (first & 0xFFFF).to_bytes(2, "big") + \
            (second & 0xFFFF).to_bytes(2, "big")

    def _word_bytes(self, word: int) -> bytes:
        data = (word & 0xFFFF).to_bytes(2, "big")
        return data[::-1] if self.little_endian() else data

    def _submit(self, pdu: bytes, origin: str, label: str = "") -> None:
        self._queue.append(Request(rtu_frame(SLAVE_ADDRESS, pdu), origin, label))
        self._start_next()

    # -- the line ---------------------------------------------------------------------
    def add_listener(self, listener: ByteListener) -> Callable[[], None]:
        """Receive every byte the motor sends on COM1; returns an unsubscribe function."""
        self._listeners.append(listener)

        def remove() -> None:
            if listener in self._listeners:
                self._listeners.remove(listener)
        return remove

    def _byte_ns(self) -> int:
        return (10 * NS_PER_S) // self.baud()

    def _start_next(self) -> None:
        if self._pending is not None or not self._queue:
            return
        if self.kernel.now < self._free_at:   # keep the silent interval between messages
            self.kernel.schedule_at(self._free_at, self._start_next, priority=PRIO_IO,
                                    name="com1-next")
            return
        request = self._queue.popleft()
        self._pending = request
        self._buf.clear()
        self.sent += 1
        for listener in list(self._listeners):
            try:
                listener(request.frame)
            except Exception:  # a broken front end must not stop the motor
                log.exception("COM1 listener failed")
        wire = (len(request.frame) + request.response_length) * self._byte_ns()
        self._timeout = self.kernel.schedule(wire + RESPONSE_TIMEOUT_NS, self._timed_out,
                                             priority=PRIO_IO, name="com1-timeout")

    def _finish(self) -> None:
        if self._timeout is not None:
            self._timeout.cancel()
            self._timeout = None
        self._pending = None
        self._buf.clear()
        self._free_at = self.kernel.now + silent_interval_ns(self.baud())
        self._start_next()

    def _timed_out(self) -> None:
        self._timeout = None
        if self._pending is not None:
            self.timeouts += 1
            log.info("COM1: no answer from the Modbus slave to %s", self._pending.frame.hex(" "))
            self._finish()

    def feed(self, data: bytes) -> None:
        """Bytes from the slave, arrived at ``kernel.now``."""
        if self._pending is None or not data:
            return   # nothing asked: stray bytes are lost, as on a wire
        now = self.kernel.now
        if self._buf and now - self._last_rx >= silent_interval_ns(self.baud()):
            self._buf.clear()   # 5.6.2: a gap ends a message; the piece was illegal
        self._last_rx = now
        self._buf += data
        expected = self._expected_length()
        if expected is None or len(self._buf) < expected:
            return
        self._answer(bytes(self._buf[:expected]))

    def _expected_length(self) -> int | None:
        buf = self._buf
        if len(buf) < 2:
            return None
        if buf[1] & 0x80:
            return 5
        if buf[1] in (READ_COILS, READ_DISCRETE):
            return 5 + buf[2] if len(buf) >= 3 else None
        return 8

    def _answer(self, frame: bytes) -> None:
        request = self._pending
        assert request is not None
        if crc16(frame[:-2]) != frame[-2:] or frame[0] != SLAVE_ADDRESS:
            self.errors += 1
        elif frame[1] == request.function | 0x80:
            self.exceptions += 1
            log.info("COM1: the slave answered exception %02X", frame[2])
        elif frame[1] != request.function:
            self.errors += 1
        elif request.label:
            self._reply_word(request, frame)
        elif frame[:6] != request.frame[:6]:
            self.errors += 1
        else:
            self.answered += 1
        self._finish()

    def _reply_word(self, request: Request, frame: bytes) -> None:
        if frame[2] != 2:
            self.errors += 1
            return
        data = frame[3:5]
        if self.little_endian():
            data = data[::-1]
        word = (data[0] << 8) | data[1]
        self.answered += 1
        io = self.io_id
        self._emit(io, "reply", f"{request.label}.{io}={word:04X}", value=word,
                   origin=request.origin)
