"""Helpers of the EtherCAT tests: a veth pair per test, masters run in its namespace.

The slave runs in this process on the root-namespace end; the master (pysoem,
KickCAT) runs as a subprocess inside the namespace and prints JSON.  Names start
with ``cmecat`` and every link is deleted in a ``finally`` (lab.veth_pair).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from coolmuscle.frontends.ethercat.lab import Lab, veth_pair
from coolmuscle.frontends.ethercat.transport import FrameThread

MASTERS = Path(__file__).parent / "ethercat_masters"

needs_net_admin = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("ip") is None,
    reason="veth pairs and network namespaces need root and iproute2")


@contextlib.contextmanager
def link(name: str) -> Iterator[Lab]:
    """A veth pair ``cmecat<name>``: the master's end inside its own namespace."""
    with veth_pair(f"cmecat{name}", inside="master") as lab:
        yield lab


def master_command(lab: Lab, script: str, *args: str) -> list[str]:
    """The command that runs ``ethercat_masters/<script>`` on the lab's master side."""
    rt = ["chrt", "-f", "30"] if shutil.which("chrt") else []   # masters run real-time
    return ["ip", "netns", "exec", lab.namespace, *rt, sys.executable, str(MASTERS / script),
            lab.master_if, *args]


def run_master(lab: Lab, script: str, *args: str, timeout: float = 90.0) -> dict[str, Any]:
    """Run ``ethercat_masters/<script>`` in the lab's namespace; its JSON result."""
    cmd = master_command(lab, script, *args)
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    if done.returncode != 0:
        raise AssertionError(f"{script} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


@contextlib.contextmanager
def serving(esc: Any, iface: str) -> Iterator[FrameThread]:
    """Answer frames for ``esc`` on ``iface`` in a frame thread."""
    frames = FrameThread(esc, iface)
    frames.start()
    try:
        yield frames
    finally:
        frames.close()


def stop_sim(sim: subprocess.Popen[str], timeout: float = 20) -> str:
    """SIGTERM to a ``coolmuscle sim`` a test started, and what it wrote on stderr (killed
    when it has not ended within ``timeout`` seconds)."""
    sim.send_signal(signal.SIGTERM)
    try:
        return sim.communicate(timeout=timeout)[1]
    except subprocess.TimeoutExpired:
        sim.kill()
        return sim.communicate()[1]


MAC = b"\xff" * 6 + b"\x01" * 6 + b"\x88\xa4"


def frame(*datagrams: tuple[int, int, int, bytes]) -> bytes:
    """An EtherCAT frame of (cmd, adp, ado, data) datagrams (logical: adp<<16|ado)."""
    body = b""
    for n, (cmd, adp, ado, data) in enumerate(datagrams):
        more = 0x8000 if n < len(datagrams) - 1 else 0
        body += struct.pack("<BBHHHH", cmd, n, adp, ado, len(data) | more, 0) + data + b"\0\0"
    return MAC + struct.pack("<H", len(body) | 0x1000) + body


def datagrams(buf: bytes | bytearray) -> list[tuple[int, int, bytes, int]]:
    """(cmd, adp, data, wkc) of every datagram of a returned frame."""
    out, pos = [], 16
    while True:
        cmd, _idx, adp, _ado, ln, _irq = struct.unpack_from("<BBHHHH", buf, pos)
        n = ln & 0x7FF
        data = bytes(buf[pos + 10:pos + 10 + n])
        wkc, = struct.unpack_from("<H", buf, pos + 10 + n)
        out.append((cmd, adp, data, wkc))
        pos += 12 + n
        if not ln & 0x8000:
            return out
