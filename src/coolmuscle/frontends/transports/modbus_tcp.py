"""Modbus TCP front end: the motor's Modbus map behind MBAP framing (docs/modbus.md).

The motor itself speaks Modbus RTU (cml-users-guide.txt 5.6.1); PLCs, HMIs and
scripts also expect Modbus TCP, so this server serves the same slave (the device API's
``modbus_request``: :class:`coolmuscle.chain.firmware_modbus.slave.ModbusSlave`) with the same
addresses, map, exceptions and broadcast rule.  It owns only the framing and the sockets:

* an ADU is the 7-byte MBAP header (transaction id, protocol id 0, length, unit id)
  and the PDU; the reply carries the request's transaction id and unit id;
* a request that gets no reply on RTU (broadcast, other address, broken PDU) gets
  none here either; an ADU with a protocol id other than 0 is ignored;
* a length field outside 2..254 (a PDU holds 1..253 bytes) leaves the stream
  without framing: the connection is closed;
* the unit id is the Modbus address as on COM0 (K81, |K84|); unit 255 and, while
  K81 is 0, unit 1 also reach ID1, so the door works with COM0 in text mode.

Requests of one connection are answered in order; several clients may connect
(at most ``max_clients``).  With every place taken, a new client is admitted by
closing the connection idle longest among those that never sent a whole ADU or sent
none for ``idle_timeout`` seconds (the Implementation Guide's rule, 4.2.1:
:mod:`.stream_server`); when every connection is in use the newcomer is closed at
once.  A connection that reset is answered no more (the ADUs it left queued are
dropped, not run).  Each request runs in the
loop's thread at the wall-clock instant it arrived (``Port.call``).  The work
per wake-up is bounded (``MAX_ADUS_PER_WAKE`` requests or
``MAX_SECONDS_PER_WAKE``), so a client pipelining 64 KB of requests shares the
loop with the motor's time and the other clients; a client that does not read
its replies is no longer read (back pressure) and at most ``max_buffer`` bytes
of its replies are kept.  Binds 127.0.0.1 unless told otherwise.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from functools import partial

from ...chain.firmware_modbus.faults import tcp_reply
from ...device.api import Device
from ...errors import TransportError
from ...sim.kernel import PRIO_REPORT, Kernel
from .base import DEFAULT_MAX_BUFFER, Port
from .lograte import LogLimiter
from .stream_server import DEFAULT_IDLE_TIMEOUT, DEFAULT_MAX_CLIENTS, StreamServer

log = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 1502
READ_SIZE = 4096
#: Requests answered per wake-up, and wall time, before the others get a turn.
MAX_ADUS_PER_WAKE = 32
MAX_SECONDS_PER_WAKE = 0.01
HEADER = 7            # transaction (2), protocol (2), length (2), unit (1)
MAX_LENGTH = 254      # unit id + the largest PDU (253 bytes)


class ModbusTcpTransport(StreamServer):
    """Serve the chain's Modbus map over TCP (see module docstring)."""

    name = "modbus-tcp"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 max_buffer: int = DEFAULT_MAX_BUFFER,
                 max_clients: int = DEFAULT_MAX_CLIENTS,
                 idle_timeout: float | None = DEFAULT_IDLE_TIMEOUT) -> None:
        super().__init__(host, port, max_clients=max_clients, idle_timeout=idle_timeout)
        self.max_buffer = max_buffer
        self._device: Device | None = None
        self.requests = 0
        self.closed_connections = 0
        self._log_unframed = LogLimiter(log, logging.INFO, "unframed connections closed")

    async def start(self, port: Port) -> None:
        from ...chain.firmware_modbus.slave import firmware_name, supports_modbus

        self.port = port
        device = port.device
        if not supports_modbus(device):
            raise TransportError(f"modbus-tcp: firmware {firmware_name(device)} has no "
                                 "Modbus (K78-K85 are other parameters there)")
        self._device = device
        await self.listen()

    async def close(self) -> None:
        await self.close_server()
        self.finished.set()

    # -- one connection ---------------------------------------------------------------
    async def serve_connection(self, reader: asyncio.StreamReader,
                               writer: asyncio.StreamWriter, peer: str) -> None:
        buf = bytearray()
        outbox = _Outbox(writer)
        while True:
            data = await reader.read(READ_SIZE)
            if not data:
                break
            buf += data
            while True:
                if writer.transport.is_closing():
                    return                     # reset or closed: answer it no more
                before = self.requests
                out, ok, more = self._take_adus(buf, outbox)
                if self.requests != before:
                    self.request_seen(writer)
                if out:
                    outbox.send(bytes(out))    # after any reply a wire fault holds
                    if writer.transport.get_write_buffer_size() > self.max_buffer:
                        await writer.drain()   # it does not read: read no more of it
                if not ok or not more:
                    break
                await asyncio.sleep(0)         # the budget is spent: others' turn
            if not ok:
                self.closed_connections += 1
                self._log_unframed("modbus-tcp: %s sent a frame without valid length; "
                                   "closed", peer)
                break

    def _take_adus(self, buf: bytearray,
                   outbox: _Outbox | None = None) -> tuple[bytearray, bool, bool]:
        """Answer the complete ADUs at the start of ``buf`` (consumed) within the
        per-wake-up budget; ``ok`` is ``False`` when the stream lost its framing,
        ``more`` is ``True`` when the budget ran out before the complete ADUs did.
        A reply a wire fault holds back goes to ``outbox`` (after the ones before it)."""
        out = bytearray()
        budget = MAX_ADUS_PER_WAKE
        deadline = time.perf_counter() + MAX_SECONDS_PER_WAKE
        while len(buf) >= HEADER:
            length = (buf[4] << 8) | buf[5]
            if not 2 <= length <= MAX_LENGTH:
                return out, False, False
            total = 6 + length
            if len(buf) < total:
                break
            if budget <= 0 or time.perf_counter() > deadline:
                return out, True, True
            budget -= 1
            adu = bytes(buf[:total])
            del buf[:total]
            if adu[2:4] != b"\x00\x00":
                continue   # not Modbus (protocol id 0)
            self.requests += 1
            reply = self._answer(adu[6], adu[7:])
            if not reply:
                continue
            answer = adu[0:4] + (len(reply) + 1).to_bytes(2, "big") + adu[6:7] + reply
            if self._device is not None and self._device.wire_faults.live("modbus-tcp"):
                answer, late = self._fault(answer)
                if late and outbox is not None:
                    outbox.send(bytes(out))
                    out.clear()
                    self._hold(outbox, answer, late)
                    continue
            out += answer
        return out, True, False

    def _fault(self, answer: bytes) -> tuple[bytes, int]:
        """The reply as the ``modbus-tcp`` wire faults make it, and how late (ns)."""
        assert self.port is not None and self._device is not None
        faults = self._device.wire_faults
        fate = self.port.call(tcp_reply, faults, answer[6], answer)
        return answer[:6] + bytes((fate.unit,)) + answer[7:], fate.late

    def _hold(self, outbox: _Outbox, answer: bytes, late: int) -> None:
        """Send ``answer`` ``late`` ns of virtual time from now (the kernel's event)."""
        assert self.port is not None and self._device is not None
        kernel = self._device.kernel
        self.port.call(lambda: outbox.hold(kernel, answer, kernel.now + late))

    def _answer(self, unit: int, pdu: bytes) -> bytes | None:
        assert self.port is not None
        try:
            answer: bytes | None = self.port.call(self._handle, unit, pdu)
            return answer
        except Exception:
            self.port.errors += 1
            log.exception("modbus-tcp: the model failed on %s", pdu[:16].hex(" "))
            return None

    def _handle(self, unit: int, pdu: bytes) -> bytes | None:
        assert self._device is not None
        return self._device.modbus_request(unit, pdu, tcp=True)


class _Outbox:
    """One connection's replies in order: a reply a wire fault holds back (``late``)
    holds the ones after it too, as bytes on one TCP stream do."""

    def __init__(self, writer: asyncio.StreamWriter) -> None:
        self.writer = writer
        #: replies not yet written, in order; ``[None]`` a place held for a late one
        self._queue: deque[list[bytes | None]] = deque()
        self._free_at = 0

    def send(self, data: bytes) -> None:
        if not data:
            return
        if self._queue:
            self._queue.append([data])
        else:
            self._write(data)

    def hold(self, kernel: Kernel, data: bytes, at: int) -> None:
        """``data`` goes out at virtual time ``at``, and not before what is held."""
        place: list[bytes | None] = [None]
        self._queue.append(place)
        self._free_at = at = max(at, self._free_at)
        kernel.schedule_at(at, partial(self._ready, place, data), priority=PRIO_REPORT,
                           name="modbus-tcp fault")

    def _ready(self, place: list[bytes | None], data: bytes) -> None:
        place[0] = data
        while self._queue and self._queue[0][0] is not None:
            ready = self._queue.popleft()[0]
            if ready is not None:
                self._write(ready)

    def _write(self, data: bytes) -> None:
        if not self.writer.transport.is_closing():
            self.writer.write(data)
