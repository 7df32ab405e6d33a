"""Helpers of the EtherNet/IP tests and bench/bench_enip.py (plain Python, no pytest): a
virtual CM1 behind the adapter, in a thread or a process, and kernel receive times of
the Class 1 packets an originator gets."""

from __future__ import annotations

import contextlib
import os
import re
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from coolmuscle.chain import Chain
from coolmuscle.frontends.enip.server import EnipTransport
from coolmuscle.frontends.transports.service import ServiceThread

SRC = Path(__file__).resolve().parents[1] / "src"
BANNER = re.compile(r"enip: ([\d.]+):(\d+) \(I/O udp (\d+)\)")


@contextlib.contextmanager
def enip_service(scale: float = 1.0) -> Iterator[ServiceThread]:
    """A CM1 chain and the adapter on free loopback ports, in a background thread."""
    st = ServiceThread(lambda: Chain(None, 1, firmware="cm1", state_dir=None),
                       lambda: [EnipTransport(port=0, io_port=0)], scale=scale)
    st.start()
    try:
        yield st
    finally:
        st.stop()


def ports(st: ServiceThread) -> tuple[int, int]:
    info = st.transports[0].info()
    return info["port"], info["io_port"]


@contextlib.contextmanager
def enip_process(*extra: str) -> Iterator[tuple[subprocess.Popen[str], int, int]]:
    """``coolmuscle sim --firmware cm1 --enip 127.0.0.1:0`` as its own process."""
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "coolmuscle", "sim", "--firmware", "cm1", "--no-state",
         "--enip", "127.0.0.1:0", "--enip-io-port", "0", *extra],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        text=True, env=env)
    try:
        deadline, seen = time.monotonic() + 30, ""
        assert proc.stderr is not None
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            if not line:
                raise RuntimeError(f"sim ended: {seen}")
            seen += line
            match = BANNER.search(line)
            if match:
                yield proc, int(match.group(2)), int(match.group(3))
                break
        else:
            raise RuntimeError(f"no banner: {seen}")
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


#: Linux's SO_TIMESTAMPNS (SCM_TIMESTAMPNS) where the socket module does not name it.
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)


class KernelStamps:
    """Stands in for the originator's UDP socket: its ``recvfrom`` goes through
    ``recvmsg`` and keeps the kernel's receive time of every T->O packet, so the
    intervals measured are the adapter's, not the receiving thread's scheduling."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.times: list[float] = []
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)

    def fileno(self) -> int:
        return self.sock.fileno()

    def close(self) -> None:
        self.sock.close()

    def recvfrom(self, size: int) -> tuple[bytes, object]:
        data, ancillary, _flags, addr = self.sock.recvmsg(size, 64)
        for level, kind, raw in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
                sec, nsec = struct.unpack_from("qq", raw)
                self.times.append(sec + nsec / 1e9)
        return data, addr
