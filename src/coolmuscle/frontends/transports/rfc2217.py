"""RFC 2217 serial port server: the host line as a COM port over Telnet (``sim --rfc2217``).

A program that opens ``rfc2217://HOST:PORT`` (pyserial) or a virtual COM port tool
that speaks RFC 2217 (com0com's hub4com ``com2tcp-rfc2217``, a terminal program's
"Telnet COM port" mode) reaches the motor's host line as a serial port it configures.
Telnet and the COM-PORT-OPTION negotiation are pyserial's
:class:`serial.rfc2217.PortManager`; this module owns the port it configures
(:class:`ComPort`: what a real port server's UART would be set to) and the TCP side,
shared with the ``tcp`` transport (bounded output, connection limit and idle policy,
one :class:`~coolmuscle.frontends.transports.base.Lane` per client; a connection
refused or closed by the idle policy is closed without a word: every byte a COM port
delivers is the motor's).

What a client's settings do (docs/transports.md "RFC 2217", docs/fidelity.md "Baud rate
of the host"):

* **baud rate**: the host's rate, told to the host line exactly as the pty tells the
  rate its client set: with wire pacing (``--pace``) a rate other than K20 reads garbage
  both ways (:mod:`coolmuscle.device.uart`); the motor does not follow it (ch. 3 K20 is
  the motor's own setting, changed by ``K20`` alone);
* **data size, parity, stop size**: the host's frame, told to the host line beside the
  rate (5.6.1: the motor frames 8 data bits, K82 parity, 1 stop bit);
* **flow control, DTR, RTS**: accepted and answered; they change nothing (the manual
  names no handshake line of COM0); CTS, DSR and CD read active, RI inactive;
* **break**: with pacing the motor's UART reads it as one 0x00 (a framing error);
* **purge**: the receive buffer is the output not yet handed to the client's socket,
  the transmit buffer the client's bytes not yet on the line.

Each client is a host of the line as a TCP client is (several may share it); bytes
0xFF of the motor's output are doubled (Telnet IAC), a client's doubled IAC is one 0xFF.
"""

from __future__ import annotations

import asyncio
import logging
import struct
from collections.abc import Callable
from typing import Any, cast

import serial
from serial.rfc2217 import (
    IAC,
    IAC_DOUBLED,
    M_NORMAL,
    SERVER_SET_CONTROL,
    SET_CONTROL,
    SET_CONTROL_BREAK_OFF,
    SET_CONTROL_BREAK_ON,
    SET_CONTROL_DTR_OFF,
    SET_CONTROL_DTR_ON,
    SET_CONTROL_REQ_BREAK_STATE,
    SET_CONTROL_REQ_DTR,
    SET_CONTROL_REQ_RTS,
    SET_CONTROL_RTS_OFF,
    SET_CONTROL_RTS_ON,
    PortManager,
)

from ...device.hostline import BAUD_RATES
from ...device.uart import MAX_HOST_BAUD, MIN_HOST_BAUD, Frame
from .base import DEFAULT_MAX_BUFFER, Lane, Port
from .stream_server import DEFAULT_IDLE_TIMEOUT, DEFAULT_MAX_CLIENTS, StreamServer
from .tcp import DEFAULT_HOST, READ_SIZE, TcpTransport, _Client

log = logging.getLogger(__name__)

#: The port a Telnet COM port server listens on when asked for none in particular.
DEFAULT_PORT = 2217

#: SET-CONTROL values of the inbound flow control (RFC 2217): a request for the setting,
#: then none, XON/XOFF, hardware, DCD, DTR, DSR.
_REQ_FLOW_IN = 13
_FLOW_IN = range(14, 20)


class ComPort:
    """The serial port a client configures, as :class:`~serial.rfc2217.PortManager`
    reads and sets it (the attributes of a pyserial port).

    A value a real UART cannot take raises ``ValueError``: the manager then answers
    with the value kept, as a port server does.  Until the client sets them the port
    is at the motor's rate (``motor_baud``) and frame: :meth:`host_baud` and
    :meth:`host_frame` are ``None`` (matched).  ``on_break`` is called when the client
    starts a break; ``on_purge_in`` / ``on_purge_out`` empty the buffers."""

    def __init__(self, motor_baud: Callable[[], int] = lambda: 38400) -> None:
        self._motor_baud = motor_baud
        self._baudrate: int | None = None
        self._framed = False
        self._bytesize = 8
        self._parity = serial.PARITY_NONE
        self._stopbits: float = serial.STOPBITS_ONE
        self.xonxoff = False
        self.rtscts = False
        self.dtr = True
        self.rts = True
        self._break = False
        self.flow_in = 14                         # RFC 2217: no inbound flow control
        self.on_break: Callable[[], None] | None = None
        self.on_purge_in: Callable[[], None] | None = None
        self.on_purge_out: Callable[[], None] | None = None

    # -- what the client sets -----------------------------------------------------
    @property
    def baudrate(self) -> int:
        return self._baudrate if self._baudrate is not None else self._motor_baud()

    @baudrate.setter
    def baudrate(self, value: int) -> None:
        if not isinstance(value, int) or not MIN_HOST_BAUD <= value <= MAX_HOST_BAUD:
            # pyserial's PortManager keeps the rate it had and answers with it
            raise ValueError(f"not a baud rate of a serial port: {value!r} (a port is set "
                             f"to {MIN_HOST_BAUD} to {MAX_HOST_BAUD} bit/s)")
        self._baudrate = value

    def host_baud(self) -> int | None:
        """The rate the client set, ``None`` before it set one."""
        return self._baudrate

    @property
    def bytesize(self) -> int:
        return self._bytesize

    @bytesize.setter
    def bytesize(self, value: int) -> None:
        if value not in serial.Serial.BYTESIZES:
            raise ValueError(f"not a data size: {value!r}")
        self._bytesize = value
        self._framed = True

    @property
    def parity(self) -> str:
        return self._parity

    @parity.setter
    def parity(self, value: str) -> None:
        if value not in serial.Serial.PARITIES:
            raise ValueError(f"not a parity: {value!r}")
        self._parity = value
        self._framed = True

    @property
    def stopbits(self) -> float:
        return self._stopbits

    @stopbits.setter
    def stopbits(self, value: float) -> None:
        if value not in serial.Serial.STOPBITS:
            raise ValueError(f"not a stop size: {value!r}")
        self._stopbits = value
        self._framed = True

    @property
    def break_condition(self) -> bool:
        return self._break

    @break_condition.setter
    def break_condition(self, value: bool) -> None:
        started = value and not self._break
        self._break = bool(value)
        if started and self.on_break is not None:
            self.on_break()

    def host_frame(self) -> Frame | None:
        """How the client set this port to frame a byte (data bits, parity, stop bits),
        ``None`` before it set any of them."""
        return Frame(self._bytesize, self._parity, self._stopbits) if self._framed else None

    # -- the lines the motor side presents --------------------------------------------
    #: The manual names no handshake line of COM0: the port reads the device ready.
    cts = True
    dsr = True
    cd = True
    ri = False

    # -- purge ------------------------------------------------------------------------
    def reset_input_buffer(self) -> None:
        if self.on_purge_in is not None:
            self.on_purge_in()

    def reset_output_buffer(self) -> None:
        if self.on_purge_out is not None:
            self.on_purge_out()


class _Manager(PortManager):
    """pyserial's port manager, with the answers a port server owes that it leaves out
    (the state of DTR, RTS, break and inbound flow control on request) and a malformed
    option ignored instead of raised (bad input never ends the connection)."""

    def __init__(self, com: ComPort, connection: _Wire) -> None:
        super().__init__(cast(Any, com), cast(Any, connection), log)
        self.com = com

    def _telnet_process_subnegotiation(self, suboption: bytes) -> None:
        try:
            if not self._answer_request(suboption):
                super()._telnet_process_subnegotiation(suboption)  # type: ignore[misc]
        except (struct.error, KeyError, TypeError, IndexError, ValueError) as exc:
            log.info("rfc2217: malformed option %r ignored (%s)", suboption[:16], exc)

    def _answer_request(self, suboption: bytes) -> bool:
        """Answer what the manager would not; ``False`` when it is the manager's."""
        if suboption[1:2] != SET_CONTROL or len(suboption) < 3:
            return False
        value = suboption[2:3]
        answer = {SET_CONTROL_REQ_DTR: SET_CONTROL_DTR_ON if self.com.dtr
                  else SET_CONTROL_DTR_OFF,
                  SET_CONTROL_REQ_RTS: SET_CONTROL_RTS_ON if self.com.rts
                  else SET_CONTROL_RTS_OFF,
                  SET_CONTROL_REQ_BREAK_STATE: SET_CONTROL_BREAK_ON
                  if self.com.break_condition else SET_CONTROL_BREAK_OFF}.get(value)
        if answer is None and value[0] == _REQ_FLOW_IN:
            answer = bytes([self.com.flow_in])
        elif answer is None and value[0] in _FLOW_IN:
            self.com.flow_in = value[0]
            answer = value
        if answer is None:
            return False
        self.rfc2217_send_subnegotiation(SERVER_SET_CONTROL, answer)
        return True


class _Wire:
    """The manager's ``connection``: Telnet bytes to one client, in order with the data."""

    def __init__(self, server: Rfc2217Transport, client: _Client) -> None:
        self.server = server
        self.client = client

    def write(self, data: bytes) -> None:
        self.server._queue(self.client, data)


class Rfc2217Transport(TcpTransport):
    """Serve the host line as an RFC 2217 serial port (see the module docstring)."""

    name = "rfc2217"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 max_buffer: int = DEFAULT_MAX_BUFFER,
                 max_clients: int = DEFAULT_MAX_CLIENTS,
                 idle_timeout: float | None = DEFAULT_IDLE_TIMEOUT) -> None:
        super().__init__(host, port, max_buffer=max_buffer, max_clients=max_clients,
                         idle_timeout=idle_timeout)

    async def start(self, port: Port) -> None:
        self.port = port
        self._loop = asyncio.get_running_loop()
        await self.listen()

    def refuse(self, writer: asyncio.StreamWriter) -> None:
        writer.transport.close()        # no words: a COM port's bytes are the motor's

    def evict(self, writer: asyncio.StreamWriter, idle: float) -> None:
        StreamServer.evict(self, writer, idle)

    async def serve_connection(self, reader: asyncio.StreamReader,
                               writer: asyncio.StreamWriter, peer: str) -> None:
        assert self.port is not None
        lane = self.port.open_lane("rfc2217")
        client = _Client(reader, writer, lane, peer)
        com = ComPort(self._motor_baud)
        room = asyncio.Event()
        room.set()
        lane.set_flow(room.clear, room.set)
        self._clients.append(client)
        unsubscribe = self._attach(client, com)
        manager = _Manager(com, _Wire(self, client))
        self._log_connection("rfc2217: client %s connected", peer)
        try:
            while not client.dropped:
                data = await reader.read(READ_SIZE)
                if not data:
                    break
                data = _data_of(manager, data)
                if b"\r" in data or b"\n" in data:   # a whole line: in use (idle policy)
                    client.spoke = True
                    self.request_seen(writer)
                lane.feed(data)
                await room.wait()
                if client.unread() and not client.dropped:
                    await writer.drain()
        finally:
            unsubscribe()
            self._clients.remove(client)
            lane.close()
            self._log_connection("rfc2217: client %s disconnected", peer)

    def _attach(self, client: _Client, com: ComPort) -> Callable[[], None]:
        """Wire ``com`` to the host line for ``client``'s lane; the unsubscriber."""
        assert self.port is not None
        port, lane = self.port, client.lane
        port.set_host_baud(lane, com.host_baud)
        port.set_host_frame(lane, com.host_frame)
        com.on_purge_in = client.pending.clear
        com.on_purge_out = lane.purge
        com.on_break = lambda: self._break(lane)
        return port.add_listener(lambda data: self._queue(client, _escape(data)), lane)

    def _motor_baud(self) -> int:
        """The motor's K20 rate (ch. 3 K20), what a port not yet set is at."""
        assert self.port is not None
        try:
            return BAUD_RATES.get(self.port.device.get_param(1, 20), 38400)
        except Exception:           # no K20 on this device: the factory rate
            return 38400

    def _break(self, lane: Lane) -> None:
        """A break on the wire: the motor's UART reads one 0x00 (a framing error)."""
        assert self.port is not None
        if getattr(self.port.host_line, "pacing", False):
            lane.feed(b"\x00")

    def _queue(self, client: _Client, data: bytes) -> None:
        """Hand ``data`` to one client's socket soon (at once beyond the bound)."""
        if client.dropped or not data:
            return
        client.pending += data
        if len(client.pending) >= self.max_buffer:
            self._flush(client)
        elif not client.flush_scheduled and self._loop is not None:
            client.flush_scheduled = True
            self._loop.call_soon(self._flush, client)


def _escape(data: bytes) -> bytes:
    """The motor's bytes as Telnet data (IAC doubled)."""
    return data.replace(IAC, IAC_DOUBLED) if IAC in data else data


def _data_of(manager: PortManager, data: bytes) -> bytes:
    """The serial data in ``data`` (Telnet commands go to the manager)."""
    if IAC not in data and manager.mode == M_NORMAL and manager.suboption is None:
        return data
    return b"".join(manager.filter(data))
