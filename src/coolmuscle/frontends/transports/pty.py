"""Pseudo-terminal transport: a serial port that serial programs open by path.

Owns one ``os.openpty()`` pair.  The slave side (``/dev/pts/N``) is put in raw mode
(no tty echo, no CR/LF translation; the motor does its own echo) and kept open by
us, so the port stays usable across client opens and closes.  Programs open it like
a serial port: ``serial.Serial("/dev/pts/N")``, minicom, screen, cutecom.  An
optional ``link`` gives it a stable path (a symlink replaced on start, removed on
close; an existing non-symlink file is never overwritten).

A pty has no wire, but it keeps the baud rate the client set (its termios speed, read
here on our side of the pair).  With the simulator's ``--pace`` option (wire timing at
the K20 rate) the host line is told that rate: while it differs from K20 the motor
reads garbage and the client reads garbage, as a real motor and host at different
rates do (ch. 3 K20; :mod:`coolmuscle.device.uart`, docs/fidelity.md "Baud rate of
the host").  Without ``--pace`` the rate has no effect.

Output the client does not read piles up in the pty's kernel buffer and then in a
bounded buffer here; beyond ``max_buffer`` bytes new output is discarded, like
bytes on a wire nobody listens to.  Bytes sent while no program has the port open
wait in the pty buffer and are read by the next program that opens it (call
``reset_input_buffer()`` after opening if that matters).
"""

from __future__ import annotations

import asyncio
import errno
import fcntl
import logging
import os
import struct
import sys
import termios
import tty
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ...errors import TransportError
from .base import DEFAULT_MAX_BUFFER, Lane, Port, Transport

log = logging.getLogger(__name__)

READ_SIZE = 4096

#: termios speed constant -> bits per second (the rates a client can set by name).
_SPEEDS = {getattr(termios, f"B{rate}"): rate for rate in (
    50, 75, 110, 134, 150, 200, 300, 600, 1200, 1800, 2400, 4800, 9600, 19200, 38400,
    57600, 115200, 230400, 460800, 500000, 576000, 921600, 1000000)
    if hasattr(termios, f"B{rate}")}
#: Linux: a rate set by number (``BOTHER`` in c_cflag's speed), read with ``TCGETS2``
#: (asm-generic/termbits.h, ioctls.h; struct termios2: 4 flags, line, 19 cc, 2 speeds).
_BOTHER = 0o010000
_TCGETS2 = 0x802C542A
_TERMIOS2 = struct.Struct("4IB19s2I")


def client_baud(fd: int) -> int | None:
    """The baud rate the program on the other side of the pty set (its output speed),
    or ``None`` when it cannot be read."""
    try:
        speed = termios.tcgetattr(fd)[5]
    except (termios.error, OSError):
        return None
    if speed in _SPEEDS:
        return _SPEEDS[speed]
    if speed == _BOTHER and sys.platform.startswith("linux"):
        try:
            raw = fcntl.ioctl(fd, _TCGETS2, bytes(_TERMIOS2.size))
        except OSError:
            return None
        return int(_TERMIOS2.unpack(raw)[-1]) or None
    return None


class SymLink:
    """A stable path to a pseudo-terminal: a symlink made in one step (an old symlink is
    replaced, any other file never), removed only while it still points at what it was
    made for.  Used by the simulator's pty and by ``coolmuscle capture --pty``."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.made = False
        self._target: str | None = None
        self._tmp: Path | None = None

    def check(self) -> None:
        """Refuse a path that is there and is not a symlink (before anything is opened)."""
        if self.path.exists() and not self.path.is_symlink():
            raise TransportError(f"pty: {self.path} exists and is not a symlink; "
                                 "not replacing it")

    def make(self, target: str) -> None:
        self.check()
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        self._tmp, self._target = tmp, target   # removed by remove() if a signal cuts this
        try:
            if tmp.is_symlink():
                tmp.unlink()
            os.symlink(target, tmp)
            self.made = True            # from here on remove() removes what points at us
            os.replace(tmp, self.path)
        except OSError as exc:
            self.made = False
            raise TransportError(f"pty: cannot create link {self.path}: {exc}") from exc

    def remove(self) -> None:
        if not self.made:
            return
        for made in (self.path, self._tmp):
            try:
                if made is not None and made.is_symlink() and os.readlink(made) == self._target:
                    made.unlink()
            except OSError:
                pass
        self.made = False


class PtyTransport(Transport):
    """Serve the host line on a pseudo-terminal (see module docstring)."""

    name = "pty"

    def __init__(self, link: str | os.PathLike[str] | None = None, *,
                 max_buffer: int = DEFAULT_MAX_BUFFER) -> None:
        super().__init__()
        self.link = Path(link).expanduser() if link is not None else None
        self.max_buffer = max_buffer
        self.path: str | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._pending = bytearray()
        self._writer_armed = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._unsubscribe: Callable[[], None] | None = None
        self._symlink = SymLink(self.link) if self.link is not None else None
        self._lane: Lane | None = None
        self.bytes_discarded = 0

    # -- life cycle -----------------------------------------------------
    async def start(self, port: Port) -> None:
        self.port = port
        self._loop = asyncio.get_running_loop()
        try:
            master, slave = os.openpty()
        except OSError as exc:
            raise TransportError(f"pty: cannot open a pseudo-terminal: {exc}") from exc
        self._master, self._slave = master, slave
        try:
            tty.setraw(slave, termios.TCSANOW)
            os.set_blocking(master, False)
            self.path = os.ttyname(slave)
            if self._symlink is not None:
                self._symlink.make(self.path)
        except (OSError, termios.error, TransportError) as exc:
            self._close_fds()
            if isinstance(exc, TransportError):
                raise
            raise TransportError(f"pty: cannot set up the pseudo-terminal: {exc}") from exc
        self._lane = port.open_lane("pty")
        self._lane.set_flow(self._pause_reading, self._resume_reading)
        port.set_host_baud(self._lane, self._client_baud)
        self._loop.add_reader(master, self._on_readable)
        self._unsubscribe = port.add_listener(self._send, self._lane)

    def _client_baud(self) -> int | None:
        """The rate the client set on the pty now (read as bytes cross, with pacing)."""
        return client_baud(self._slave) if self._slave is not None else None

    def _pause_reading(self) -> None:
        if self._loop is not None and self._master is not None:
            self._loop.remove_reader(self._master)

    def _resume_reading(self) -> None:
        if self._loop is not None and self._master is not None:
            self._loop.add_reader(self._master, self._on_readable)

    def describe(self) -> str:
        where = self.path or "(not open)"
        if self._symlink is not None and self._symlink.made:
            return f"pty: {self.link} -> {where}"
        return f"pty: {where}"

    def info(self) -> dict[str, Any]:
        made = self._symlink is not None and self._symlink.made
        return {"path": self.path, "link": str(self.link) if made else None}

    async def close(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self._symlink is not None:
            self._symlink.remove()
        self._close_fds()
        if self._lane is not None:
            self._lane.close()
            self._lane = None
        self.finished.set()

    def _close_fds(self) -> None:
        if self._loop is not None and self._master is not None:
            self._loop.remove_reader(self._master)
            if self._writer_armed:
                self._loop.remove_writer(self._master)
                self._writer_armed = False
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None

    # -- bytes ----------------------------------------------------------
    def _on_readable(self) -> None:
        if self._master is None:
            return
        try:
            data = os.read(self._master, READ_SIZE)
        except BlockingIOError:
            return
        except OSError as exc:
            if exc.errno == errno.EIO:  # no slave open; cannot happen while we hold it
                return
            log.warning("pty: read failed: %s", exc)
            return
        if data and self._lane is not None:
            self._lane.feed(data)

    def _send(self, data: bytes) -> None:
        room = self.max_buffer - len(self._pending)
        if room < len(data):
            if room <= 0 and not self.bytes_discarded:
                log.warning("pty: nobody reads %s; discarding output beyond %d bytes",
                            self.path, self.max_buffer)
            self.bytes_discarded += len(data) - max(room, 0)
            data = data[:max(room, 0)]
        self._pending += data
        self._write_some()

    def _write_some(self) -> None:
        if self._master is None:
            self._pending.clear()
            return
        while self._pending:
            try:
                written = os.write(self._master, self._pending)
            except BlockingIOError:
                break
            except OSError as exc:
                log.warning("pty: write failed: %s", exc)
                self._pending.clear()
                break
            del self._pending[:written]
        if self._pending and not self._writer_armed and self._loop is not None:
            self._loop.add_writer(self._master, self._write_some)
            self._writer_armed = True
        elif not self._pending and self._writer_armed and self._loop is not None:
            self._loop.remove_writer(self._master)
            self._writer_armed = False
