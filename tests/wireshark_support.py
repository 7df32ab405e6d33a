"""Wireshark as an independent oracle: capture a peer session with tshark, dissect it.

The capture is a side car: :class:`Capture` runs ``tshark -i IFACE -f BPF -w FILE``
around a session that the usual peers (pysoem, pycomm3, ethernetip, pymodbus, aiohttp)
drive; :func:`dissect` reads the file back with Wireshark's own dissectors and returns
the fields asked for, frame by frame; :func:`problems` lists every frame a dissector
marked malformed or gave an expert error.  Captures need raw sockets (root or
CAP_NET_RAW); :func:`capture_unavailable` says why they cannot run here, or ``None``.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import re
import select
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

TSHARK = "tshark"
SRC = Path(__file__).resolve().parents[1] / "src"
NETNS_PREFIX = "cmws"     # the namespaces of these tests (ip netns list shows leftovers)
BANNER_TIMEOUT = 30.0     # s for ``coolmuscle sim`` to say where it listens
START_TIMEOUT = 15.0      # s until tshark says it is capturing
STOP_TIMEOUT = 10.0       # s for tshark to write the file and end
SETTLE = 0.3              # s left for the last packets before the capture stops
READ_TIMEOUT = 60.0       # s for one dissection of a file

#: Expert info severities (epan/proto.h): PI_ERROR is the one an error has.
PI_ERROR = 0x00800000
PROBLEMS = f"_ws.malformed or _ws.expert.severity >= {PI_ERROR:#x}"

#: Field values as tshark prints them: every occurrence of a field in one frame.
Frame = dict[str, list[str]]


def wait_line(stream: IO[str], pattern: re.Pattern[str], timeout: float,
              log: list[str]) -> re.Match[str] | None:
    """Read ``stream`` (a pipe) line by line until a line matches ``pattern``; the match,
    or ``None`` at its end or after ``timeout`` s.  Reads the descriptor itself, so no
    line waits in a buffer that ``select`` cannot see; lines read are added to ``log``."""
    fd, buffer = stream.fileno(), b""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 0.2)
        if not ready:
            continue
        chunk = os.read(fd, 4096)
        if not chunk:
            return None
        buffer += chunk
        while b"\n" in buffer:
            raw, buffer = buffer.split(b"\n", 1)
            line = raw.decode("utf-8", "replace") + "\n"
            log.append(line)
            match = pattern.search(line)
            if match:
                return match
    return None


def capture_unavailable() -> str | None:
    """Why a capture cannot run on this machine, or ``None`` when it can."""
    if shutil.which(TSHARK) is None:
        return "tshark is not installed (scripts/test installs Debian's tshark)"
    try:
        raw = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x0003))
    except (PermissionError, OSError) as exc:
        return f"raw sockets are not allowed here ({exc}): captures need root or CAP_NET_RAW"
    raw.close()
    return None


@dataclass
class Capture:
    """A running ``tshark`` capture on ``iface`` with the BPF ``bpf`` filter into ``path``."""

    iface: str
    path: Path
    bpf: str = ""
    namespace: str | None = None
    _proc: subprocess.Popen[str] | None = field(default=None, repr=False)
    _log: list[str] = field(default_factory=list, repr=False)

    def command(self) -> list[str]:
        cmd = [TSHARK, "-i", self.iface, "-w", str(self.path), "-q"]
        if self.bpf:
            cmd += ["-f", self.bpf]
        if self.namespace is not None:
            cmd = ["ip", "netns", "exec", self.namespace, *cmd]
        return cmd

    def start(self) -> Capture:
        """Start tshark; return once dumpcap captures (tshark says so on stderr)."""
        self._proc = subprocess.Popen(self.command(), stdin=subprocess.DEVNULL,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                      text=True, start_new_session=True)
        assert self._proc.stderr is not None
        # dumpcap's word; tshark's "Capturing on" comes some 50 ms before packets are seen
        started = wait_line(self._proc.stderr, re.compile("Capture started"), START_TIMEOUT,
                            self._log)
        if started is None:
            self.stop()
            raise RuntimeError(f"tshark did not start capturing: {''.join(self._log)}")
        return self

    def stop(self) -> Path:
        """Let the last packets arrive, stop tshark, return the capture file."""
        proc, self._proc = self._proc, None
        if proc is None:
            return self.path
        if proc.poll() is None:
            time.sleep(SETTLE)
            os.killpg(proc.pid, signal.SIGINT)
        try:
            _, rest = proc.communicate(timeout=STOP_TIMEOUT)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            _, rest = proc.communicate(timeout=STOP_TIMEOUT)
        self._log.append(rest or "")
        return self.path

    @property
    def log(self) -> str:
        return "".join(self._log)


@contextlib.contextmanager
def capturing(iface: str, path: Path, bpf: str = "",
              namespace: str | None = None) -> Iterator[Capture]:
    """:class:`Capture` as a context: tshark is always stopped, also on failure."""
    cap = Capture(iface, path, bpf, namespace).start()
    try:
        yield cap
    finally:
        cap.stop()


def decode_as(*rules: str) -> list[str]:
    """``-d`` options, e.g. ``decode_as("tcp.port==1502,mbtcp")``."""
    return [arg for rule in rules for arg in ("-d", rule)]


def _tshark_read(path: Path, args: Sequence[str]) -> str:
    done = subprocess.run([TSHARK, "-r", str(path), *args], capture_output=True, text=True,
                          timeout=READ_TIMEOUT, stdin=subprocess.DEVNULL, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"tshark -r {path} {' '.join(args)} failed ({done.returncode}): "
                           f"{done.stderr[-2000:]}")
    return done.stdout


def dissect(path: Path, fields: Sequence[str], display_filter: str = "",
            decode: Sequence[str] = ()) -> list[Frame]:
    """The frames of ``path`` that pass ``display_filter``, as {field: [values]} (only
    the fields present in a frame); ``frame.number`` is always there."""
    args = [*decode, "-T", "json", "-e", "frame.number"]
    for name in fields:
        args += ["-e", name]
    if display_filter:
        args += ["-Y", display_filter]
    text = _tshark_read(path, args).strip()
    if not text:
        return []
    packets = json.loads(text)
    return [{k: list(v) for k, v in p["_source"]["layers"].items()} for p in packets]


def problems(path: Path, decode: Sequence[str] = ()) -> list[str]:
    """Every malformed frame and expert error of ``path``, one line each (frame number,
    protocols, the expert messages)."""
    frames = dissect(path, ["frame.protocols", "_ws.expert.message", "_ws.expert.severity",
                            "_ws.malformed"], PROBLEMS, decode)
    out = []
    for f in frames:
        messages = [m for m, s in zip(f.get("_ws.expert.message", []),
                                      f.get("_ws.expert.severity", []))
                    if int(s, 0) >= PI_ERROR]
        out.append(f"frame {f['frame.number'][0]} {f.get('frame.protocols', ['?'])[0]}: "
                   f"{'malformed ' if '_ws.malformed' in f else ''}{messages}")
    return out


def protocols(path: Path, decode: Sequence[str] = ()) -> set[str]:
    """Every protocol name some frame of ``path`` was dissected with."""
    frames = dissect(path, ["frame.protocols"], "", decode)
    return {name for f in frames for p in f.get("frame.protocols", [])
            for name in p.split(":")}


def values(frames: Sequence[Frame], name: str) -> list[str]:
    """All values of field ``name`` over ``frames``, in order."""
    return [v for f in frames for v in f.get(name, [])]


def ints(frames: Sequence[Frame], name: str) -> list[int]:
    """All values of an integer field over ``frames`` (tshark prints decimal or 0x hex)."""
    return [int(v, 0) for v in values(frames, name)]


_counter = itertools.count()


@contextlib.contextmanager
def private_net() -> Iterator[str]:
    """A network namespace of its own (loopback only, up) for one capture; always deleted.

    The standard ports (44818, 2222, 502) are free there, and Wireshark classifies
    requests and responses by those ports."""
    name = f"{NETNS_PREFIX}{os.getpid() % 100_000}x{next(_counter)}"
    subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=20, check=False)
    subprocess.run(["ip", "netns", "add", name], check=True, capture_output=True, timeout=20)
    try:
        subprocess.run(["ip", "netns", "exec", name, "ip", "link", "set", "lo", "up"],
                       check=True, capture_output=True, timeout=20)
        yield name
    finally:
        subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=20,
                       check=False)


def in_net(namespace: str | None, argv: Sequence[str]) -> list[str]:
    """``argv`` run inside ``namespace`` (``None``: here)."""
    return [*argv] if namespace is None else ["ip", "netns", "exec", namespace, *argv]


@contextlib.contextmanager
def sim_process(namespace: str | None, *args: str, banner: str) -> Iterator[re.Match[str]]:
    """``coolmuscle sim --no-state ARGS`` inside ``namespace`` (``None``: here); yields the
    match of the regex ``banner`` in what it printed, and stops it afterwards."""
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    proc = subprocess.Popen(in_net(namespace, [sys.executable, "-m", "coolmuscle", "sim",
                                               "--no-state", *args]),
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
    assert proc.stderr is not None
    try:
        seen: list[str] = []
        match = wait_line(proc.stderr, re.compile(banner), BANNER_TIMEOUT, seen)
        if match is None:
            raise RuntimeError(f"sim printed no {banner!r}: {''.join(seen)}")
        yield match
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(STOP_TIMEOUT)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(STOP_TIMEOUT)
