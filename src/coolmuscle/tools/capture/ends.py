"""The two ends of the relay: the motor's port and the place the host program connects.

* :class:`MotorPort`: any pyserial URL or device (opened as the host library opens
  one, ``coolmuscle://`` included), read as soon as bytes are there: through its file
  descriptor when it has one (a serial device, ``socket://``), else by pyserial's
  ``read`` with a short timeout (``rfc2217://``, ``coolmuscle://``);
* :class:`TcpHostSide`: ``--listen [HOST:]PORT`` (127.0.0.1 by default), one host
  program at a time, as a serial port has one;
* :class:`PtyHostSide`: ``--pty LINK``, a pseudo-terminal in raw mode (no tty echo or
  line-end translation: the motor does its own) with a symlink at LINK, removed on exit
  (POSIX only: its modules are imported when it is made).

On Windows a serial port (``COM3``) has no file descriptor: the motor's side is read by
pyserial's ``read``, and a ``socket://`` link through its socket (``os.read`` there
takes no socket).
"""

from __future__ import annotations

import os
import re
import select
import socket
import sys
from pathlib import Path
from typing import Any

from ...client.sync import open_port
from ...errors import CoolMuscleError, TransportError
from ...frontends.transports.tcp import parse_address
from .settings import PARITIES

__all__ = ["LinkBroken", "MotorPort", "PtyHostSide", "TcpHostSide"]

READ_SIZE = 65536
#: pyserial's read timeout where there is no file descriptor to wait on (s).
POLL = 0.05


class LinkBroken(CoolMuscleError):
    """The motor's port failed or was closed by the other end."""


def _why(exc: TransportError, url: str) -> str:
    """The reason pyserial gives, once (its messages repeat the port and the errno)."""
    text = str(exc.__cause__ or exc).removeprefix(f"cannot open {url}: ")
    numbers = re.findall(r"\[Errno (\d+)\]", text)
    return os.strerror(int(numbers[-1])) if numbers else text


def _fileno(port: Any) -> int | None:
    if os.name != "posix":         # a socket's number is no file descriptor there
        return None
    try:
        fd = port.fileno()
    except (AttributeError, OSError, ValueError):     # io.UnsupportedOperation is an OSError
        return None
    return fd if isinstance(fd, int) and fd >= 0 else None


def _no_delay(fd: int) -> None:
    """A TCP link to the motor (``socket://``) sends each write at once (pyserial leaves
    Nagle's algorithm on; a serial device is not a socket and is left alone)."""
    try:
        with socket.socket(fileno=os.dup(fd)) as sock:
            if sock.type == socket.SOCK_STREAM and sock.family in (socket.AF_INET,
                                                                   socket.AF_INET6):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    except OSError:
        pass                       # not a socket


class MotorPort:
    """The motor's side: a pyserial port (see module docstring)."""

    def __init__(self, url: str, baud: int, parity: str) -> None:
        self.url = url
        try:
            self.port = open_port(url, baudrate=baud, parity=PARITIES[parity])
        except TransportError as exc:
            raise TransportError(f"cannot open the motor's port {url}: {_why(exc, url)}") from None
        self.port.timeout = POLL
        self._fd = _fileno(self.port)
        if self._fd is not None:
            _no_delay(self._fd)

    def read(self, timeout: float) -> bytes:
        """What has arrived (at most ``timeout`` s of waiting; ``b""``: nothing yet)."""
        try:
            if self._fd is None:
                return bytes(self.port.read(max(1, self.port.in_waiting)))
            if not select.select([self._fd], [], [], timeout)[0]:
                return b""
            data = os.read(self._fd, READ_SIZE)
        except BlockingIOError:
            return b""
        except OSError as exc:            # pyserial's SerialException is an OSError too
            raise LinkBroken(f"the link to {self.url} broke: "
                             f"{getattr(exc, 'strerror', None) or exc}") from None
        if not data:
            raise LinkBroken(f"the link to {self.url} broke: closed by the other end")
        return data

    def write(self, data: bytes) -> None:
        try:
            self.port.write(data)
        except OSError as exc:
            raise LinkBroken(f"the link to {self.url} broke: "
                             f"{getattr(exc, 'strerror', None) or exc}") from None

    def close(self) -> None:
        try:
            self.port.close()
        except OSError:
            pass


class TcpHostSide:
    """``--listen``: a TCP port the host program connects to (pyserial ``socket://``)."""

    def __init__(self, address: str) -> None:
        host, port = parse_address(address)
        try:
            infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
            family, _, _, _, where = infos[0]
            self.server = socket.socket(family, socket.SOCK_STREAM)
        except OSError as exc:
            raise TransportError(f"--listen {address}: {exc.strerror or exc}") from None
        try:
            self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.server.bind(where)
            self.server.listen(4)
            self.server.setblocking(False)
        except OSError as exc:
            self.server.close()
            raise TransportError(f"--listen {address}: {exc.strerror or exc}") from None
        bound = self.server.getsockname()
        self.host, self.port = bound[0], bound[1]

    def describe(self) -> str:
        shown = f"[{self.host}]" if ":" in self.host else self.host
        return f"socket://{shown}:{self.port}"

    def accept(self) -> tuple[socket.socket, str] | None:
        try:
            conn, peer = self.server.accept()
        except (BlockingIOError, InterruptedError):
            return None
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return conn, f"{peer[0]}:{peer[1]}"

    def close(self) -> None:
        self.server.close()


class PtyHostSide:
    """``--pty LINK``: a pseudo-terminal the host program opens as a serial port."""

    def __init__(self, link: str | os.PathLike[str]) -> None:
        import termios
        import tty

        from ...frontends.transports.pty import SymLink

        self.link = SymLink(Path(link).expanduser())
        self.link.check()
        master, slave = os.openpty()
        try:
            tty.setraw(slave, termios.TCSANOW)
            os.set_blocking(master, False)
            self.path = os.ttyname(slave)
            self.link.make(self.path)
        except (OSError, termios.error, TransportError) as exc:
            os.close(master)
            os.close(slave)
            if isinstance(exc, TransportError):
                raise
            raise TransportError(f"--pty: cannot set up the pseudo-terminal: {exc}") from exc
        self.master = master
        self._slave = slave   # held open: the port stays usable across the host's opens

    def describe(self) -> str:
        return f"{self.link.path} -> {self.path}"

    def unread(self) -> int:
        """Bytes written to the host program that it has not read yet (closing the
        pseudo-terminal would throw them away)."""
        import fcntl
        import termios

        try:
            count = fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0")
        except OSError:
            return 0
        return int.from_bytes(count, sys.byteorder)

    def close(self) -> None:
        self.link.remove()
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
