"""Load on a served chain, for the tests and the benchmarks alike (plain Python, no pytest:
bench/ imports it too, with ``tests/`` on its path).

* :func:`connect`: a TCP client of a served port (Nagle off);
* :class:`Flood`: a client that floods a port with a line and reads and drops what
  comes back, in two threads, until the ``with`` block ends (docs/reliability.md);
* :func:`round_trip`: the wall time from a query to its reply, other clients' output
  passing by;
* :func:`start_sim`, :func:`save_then_kill`, :func:`saved_value`: ``coolmuscle sim``
  as a process, saves ``$`` acknowledged one by one and a ``kill -9`` in flight
  (cml-users-guide.txt 2.1.2), and what the store holds after it;
* :func:`signal_and_wait`: a stop signal to a process (or its group, as a terminal's
  Ctrl-C) and what it printed until it ended.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

from coolmuscle.motor.state.store import Store
from fixtures import ServedSim


def connect(port: int, timeout: float = 10.0) -> socket.socket:
    """A client of ``127.0.0.1:port``, Nagle off (each query leaves at once)."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return sock


class Flood:
    """``with Flood(sock):`` - ``line`` sent ``batch`` at a time without pause (``None``:
    the caller sends what it likes through :attr:`sock`), and every byte that comes
    back read and dropped; the threads stop and the socket closes on leaving.  The
    socket's timeout becomes ``poll`` (how soon the threads see the end; also what a
    caller's own ``sendall`` on it may wait)."""

    def __init__(self, sock: socket.socket, line: bytes | None = b"?99.1\r",
                 batch: int = 100, poll: float = 0.05) -> None:
        self.sock = sock
        self.line = line
        self.batch = batch
        self.poll = poll
        self.sent = 0                                  # lines sent by the pump
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._drain, daemon=True)]
        if line is not None:
            self._threads.append(threading.Thread(target=self._pump, daemon=True))

    def __enter__(self) -> Flood:
        self.sock.settimeout(self.poll)
        for thread in self._threads:
            thread.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(5)
        self.sock.close()

    def _pump(self) -> None:
        assert self.line is not None
        data = self.line * self.batch
        while not self._stop.is_set():
            try:
                self.sock.sendall(data)
                self.sent += self.batch
            except (TimeoutError, BlockingIOError):
                continue
            except OSError:
                return

    def _drain(self) -> None:
        while not self._stop.is_set():
            try:
                if not self.sock.recv(1 << 16):
                    return
            except (TimeoutError, BlockingIOError):
                continue
            except OSError:
                return


def round_trip(sock: socket.socket, query: bytes, reply: bytes, timeout: float = 10.0,
               count: int = 1) -> float:
    """Seconds from sending ``query`` until ``count`` whole lines starting with ``reply``
    (for instance ``b"Px.2="``) arrived; what else arrives (other clients' output:
    every client sees every line) is passed over.  ``count``: the replies of a query
    sent that many times (so that none is left unread for the next one)."""
    wanted = re.compile(re.escape(reply) + rb"[^\r\n]*\r\n")
    sock.settimeout(timeout)
    start = time.perf_counter()
    sock.sendall(query)
    data = b""
    found = 0
    while found < count:
        chunk = sock.recv(1 << 16)
        if not chunk:
            raise ConnectionError(f"closed before {reply!r}; got {data[-200:]!r}")
        data += chunk
        end = 0
        for match in wanted.finditer(data):
            found, end = found + 1, match.end()
        data = data[end:] if end else data[-256:]
    return time.perf_counter() - start


def start_sim(state: Path, env: Mapping[str, str],
              *extra: str) -> tuple[subprocess.Popen[bytes], int]:
    """``coolmuscle sim --tcp 0 --state STATE`` as a process (:class:`fixtures.ServedSim`;
    what it prints goes to ``sim.log`` beside STATE), and its TCP port from the banner;
    ``RuntimeError`` when it ended before it was ready."""
    try:
        sim = ServedSim(state.parent / "sim.log", *extra, state=state, env=env)
    except AssertionError as exc:
        raise RuntimeError(f"sim ended before it was ready: {exc}") from None
    return sim.proc, sim.port


def save_then_kill(proc: subprocess.Popen[Any], port: int, last: int, seconds: float,
                   pause: float = 0.0) -> int:
    """Save ``P1.1`` = ``last`` + 1, + 2, ... (``P1.1=n`` then ``$.1``, each answered
    ``saved.1``) for ``seconds``, send one more save and ``kill -9`` the sim ``pause``
    seconds later, during that ``$``.  Returns the last acknowledged value."""
    acknowledged = last
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        deadline = time.monotonic() + seconds
        data = b""
        while time.monotonic() < deadline:
            sock.sendall(b"P1.1=%d\r$.1\r" % (acknowledged + 1))
            while b"saved.1" not in data:
                data += sock.recv(4096)
            data = data.split(b"saved.1", 1)[1]
            acknowledged += 1
        sock.sendall(b"P1.1=%d\r$.1\r" % (acknowledged + 1))
        if pause:
            time.sleep(pause)
        os.kill(proc.pid, signal.SIGKILL)
    proc.wait(10)
    return acknowledged


def saved_value(state: Path) -> tuple[bool, int]:
    """(the store passes SQLite's integrity check, the ``P1.1`` it holds for ID1)."""
    with Store(state / "coolmuscle.sqlite3") as store:
        whole = store.integrity_check() == "ok"
        return whole, int(store.load(1)["memory"]["P"][1])


def signal_and_wait(proc: subprocess.Popen[Any], sig: int = signal.SIGINT, *,
                    group: bool = False, timeout: float = 30.0) -> tuple[Any, Any]:
    """Send ``sig`` to ``proc`` (to its whole process group with ``group``: start it
    with ``start_new_session=True``), wait for its end and return its (stdout, stderr);
    a process still running after ``timeout`` is killed (and the wait fails)."""
    try:
        if group:
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
        return proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
