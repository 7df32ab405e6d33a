"""Helpers of the EtherNet/IP tests: a virtual CM1 behind the adapter, in a thread or a process."""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterator

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
