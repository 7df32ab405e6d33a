"""Serial lines: COM0 on a serial device, COM0 in Modbus RTU mode, and COM1 (docs/modbus.md).

Three front ends share one non-blocking file-descriptor pump (:class:`_FdPump`):

* :class:`SerialTransport` (``serial-device``): the host line (COM0) on a serial
  device or on a pseudo-terminal another program made (``socat`` pty pairs),
  configured at the K20 baud rate and K82 parity, 8 data bits, 1 stop bit (5.6.1);
* :class:`ModbusRtuTransport` (``modbus-rtu``, ``coolmuscle sim --modbus-rtu``): the
  same on a device, or on a new pseudo-terminal (``pty``), with COM0 put in Modbus
  mode: when ID1's K81 is 0 it is set to 1 (station address 1), as a user would
  before switching the host to Modbus (ch. 3 K81; it persists like any K write);
* :class:`Com1Transport` (``com1``, ``coolmuscle sim --com1``): COM1 of the final
  motor (the chain's :class:`~coolmuscle.chain.firmware_modbus.master.Com1Port`) on a
  device or a new pseudo-terminal, at the final motor's K65 baud rate and K82 parity.

Bytes received are delivered at the wall-clock instant they arrive (the real-time
driver catches the kernel up first), so the 5.6.2 silent interval is measured in
virtual time that follows the wall clock.  A device's baud rate and parity follow
the parameters when they change.  Output nobody reads is bounded (1 MiB) and then
discarded, like bytes on a wire nobody listens to.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import os
from collections.abc import Callable
from typing import Any

from ...device.api import Com1Line, Device
from ...errors import TransportError
from .base import DEFAULT_MAX_BUFFER, Port, Transport

log = logging.getLogger(__name__)

READ_SIZE = 4096
Settings = Callable[[], tuple[int, str]]


class _FdPump:
    """Move bytes between a non-blocking fd and callbacks inside the asyncio loop."""

    def __init__(self, fd: int, on_data: Callable[[bytes], None], label: str,
                 max_buffer: int = DEFAULT_MAX_BUFFER) -> None:
        self.fd: int | None = fd
        self.label = label
        self.max_buffer = max_buffer
        self._on_data = on_data
        self._pending = bytearray()
        self._writer_armed = False
        self._loop = asyncio.get_running_loop()
        self._loop.add_reader(fd, self._readable)
        self.bytes_discarded = 0

    def _readable(self) -> None:
        if self.fd is None:
            return
        try:
            data = os.read(self.fd, READ_SIZE)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            if exc.errno != errno.EIO:   # EIO: the other side of a pty is closed
                log.warning("%s: read failed: %s", self.label, exc)
            return
        if data:
            try:
                self._on_data(data)
            except Exception:  # the pump must go on for the next bytes
                log.exception("%s: delivering %d bytes failed", self.label, len(data))

    def send(self, data: bytes) -> None:
        room = self.max_buffer - len(self._pending)
        if room < len(data):
            self.bytes_discarded += len(data) - max(room, 0)
            data = data[:max(room, 0)]
        self._pending += data
        self._write_some()

    def _write_some(self) -> None:
        if self.fd is None:
            self._pending.clear()
            return
        while self._pending:
            try:
                written = os.write(self.fd, self._pending)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                log.warning("%s: write failed: %s", self.label, exc)
                self._pending.clear()
                break
            del self._pending[:written]
        if self._pending and not self._writer_armed:
            self._loop.add_writer(self.fd, self._write_some)
            self._writer_armed = True
        elif not self._pending and self._writer_armed:
            self._loop.remove_writer(self.fd)
            self._writer_armed = False

    def close(self) -> None:
        if self.fd is None:
            return
        self._loop.remove_reader(self.fd)
        if self._writer_armed:
            self._loop.remove_writer(self.fd)
            self._writer_armed = False
        self.fd = None


class _Device:
    """A serial device (or somebody else's pty) opened with pyserial, kept configured."""

    def __init__(self, path: str, settings: Settings) -> None:
        import serial

        self.path = path
        self._settings = settings
        baud, parity = settings()
        try:
            self.serial = serial.Serial(path, baudrate=baud, parity=parity, bytesize=8,
                                        stopbits=1, timeout=0, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise TransportError(f"cannot open serial port {path}: {exc}") from exc
        self._applied = (baud, parity)

    @property
    def fd(self) -> int:
        return int(self.serial.fileno())

    def follow_settings(self) -> None:
        """Re-apply baud rate and parity when the parameters changed."""
        wanted = self._settings()
        if wanted != self._applied:
            self._applied = wanted   # tried once per change; a refusal is not retried
            baud, parity = wanted
            for name, value in (("baudrate", baud), ("parity", parity)):
                try:
                    setattr(self.serial, name, value)
                except Exception as exc:   # termios.error, SerialException, ValueError
                    # A pty has no parity bits: Linux refuses PARENB there.
                    log.warning("%s: cannot set %s %s: %s", self.path, name, value, exc)

    def close(self) -> None:
        try:
            self.serial.close()
        except OSError:
            pass


def _new_pty() -> tuple[int, int, str]:
    import termios  # POSIX only, as pseudo-terminals are (coolmuscle.needs)
    import tty

    master, slave = os.openpty()
    tty.setraw(slave, termios.TCSANOW)
    os.set_blocking(master, False)
    return master, slave, os.ttyname(slave)


class _PumpedLine(Transport):
    """A line whose bytes a :class:`_FdPump` moves to and from a file descriptor (a
    serial device, whose settings follow the parameters, or a pseudo-terminal)."""

    def __init__(self, path: str | None) -> None:
        super().__init__()
        self.path = path
        self._dev: _Device | None = None
        self._pump: _FdPump | None = None
        self._unsubscribe: Callable[[], None] | None = None

    def _send(self, data: bytes) -> None:
        if self._pump is not None:
            if self._dev is not None:
                self._dev.follow_settings()
            self._pump.send(data)

    def info(self) -> dict[str, Any]:
        return {"path": self.path}

    def _release(self) -> None:
        """What a subclass holds beyond the pump and the device."""

    async def close(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self._pump is not None:
            self._pump.close()
        if self._dev is not None:
            self._dev.close()
        self._release()
        self.finished.set()


class SerialTransport(_PumpedLine):
    """The host line (COM0) on a serial device, at K20 baud and K82 parity."""

    name = "serial-device"

    def __init__(self, path: str) -> None:
        super().__init__(path)
        self.path: str = path

    def _settings(self) -> tuple[int, str]:
        from ...chain.firmware_modbus.rtu import byte_baud
        assert self.port is not None
        device = self.port.device
        return byte_baud(device.get_param(1, 20)), "NEO"[device.get_param(1, 82) % 3]

    async def start(self, port: Port) -> None:
        self.port = port
        self._dev = _Device(self.path, self._settings)
        self._pump = _FdPump(self._dev.fd, self._received, f"serial {self.path}")
        self._unsubscribe = port.add_listener(self._send)

    def _received(self, data: bytes) -> None:
        assert self.port is not None and self._dev is not None
        self._dev.follow_settings()
        self.port.feed(data)

    def describe(self) -> str:
        return f"serial: {self.path}"


def ensure_modbus_mode(device: Device) -> int:
    """Put COM0 in Modbus mode (K81.1=1 when it is 0); return the station address."""
    k81 = device.get_param(1, 81)
    if k81 == 0:
        device.set_param(1, 81, 1)
        k81 = 1
    return abs(k81)


class ModbusRtuTransport(Transport):
    """COM0 in Modbus RTU mode on a new pty (``"pty"``) or a serial device path."""

    name = "modbus-rtu"

    def __init__(self, where: str = "pty", *, link: str | os.PathLike[str] | None = None) -> None:
        super().__init__()
        self.where = where
        if where == "pty":
            from .pty import PtyTransport  # POSIX only (coolmuscle.needs)
            self.inner: Transport = PtyTransport(link)
        else:
            self.inner = SerialTransport(where)
        self.station = 0

    async def start(self, port: Port) -> None:
        from ...chain.firmware_modbus.slave import firmware_name, supports_modbus
        self.port = port
        if not supports_modbus(port.device):
            raise TransportError(f"modbus-rtu: firmware {firmware_name(port.device)} has no "
                                 "Modbus")
        self.station = port.call(ensure_modbus_mode, port.device)
        await self.inner.start(port)

    def describe(self) -> str:
        where = self.inner.describe().split(": ", 1)[-1]
        return f"modbus-rtu: {where} (station {self.station})"

    def info(self) -> dict[str, Any]:
        return {**self.inner.info(), "station": self.station}

    async def close(self) -> None:
        await self.inner.close()
        self.finished.set()


class Com1Transport(_PumpedLine):
    """COM1 of the final motor, a Modbus host when its K84 is 1, on a pty or a device."""

    name = "com1"

    def __init__(self, where: str = "pty") -> None:
        super().__init__(None)
        self.where = where
        self._fds: tuple[int, int] | None = None
        self._com1: Com1Line | None = None

    def _settings(self) -> tuple[int, str]:
        assert self._com1 is not None
        return self._com1.baud(), self._com1.parity()

    async def start(self, port: Port) -> None:
        self.port = port
        com1 = self._com1 = port.device.com1
        if self.where == "pty":
            try:
                master, slave, self.path = _new_pty()
            except OSError as exc:
                raise TransportError(f"com1: cannot open a pseudo-terminal: {exc}") from exc
            self._fds = (master, slave)
            fd = master
        else:
            self._dev = _Device(self.where, self._settings)
            self.path, fd = self.where, self._dev.fd
        self._pump = _FdPump(fd, self._received, f"com1 {self.path}")
        self._unsubscribe = com1.add_listener(self._send)

    def _received(self, data: bytes) -> None:
        assert self.port is not None and self._com1 is not None
        if self._dev is not None:
            self._dev.follow_settings()
        self.port.call(self._com1.feed, data)

    def describe(self) -> str:
        return f"com1: {self.path or self.where}"

    def _release(self) -> None:
        if self._fds is not None:
            for fd in self._fds:
                try:
                    os.close(fd)
                except OSError:
                    pass
            self._fds = None
