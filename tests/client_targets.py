"""The three targets the host library is tested against, with the same results expected.

* ``inproc``: ``coolmuscle://?mode=fast`` - the simulator in-process, virtual time;
* ``tcp``: the simulator in a :class:`ServiceThread` behind a :class:`TcpTransport`,
  real time, reached as ``socket://``;
* ``pty``: the same service bridged by ``socat`` to a pseudo-terminal that pyserial
  opens as a real serial port (``serial.Serial("/dev/pts/N")``, termios and all).

Each target gives a URL, opens clients, and runs code in the model's thread at the
current virtual instant (``inject``: alarms and other faults), so one test body runs
unchanged on all three.
"""

from __future__ import annotations

import shutil
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from coolmuscle.chain.daisy import Chain
from coolmuscle.client import CoolMuscle, connect
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport
from coolmuscle.sim.kernel import seconds
from fixtures import wait_until

TARGETS = ("inproc", "tcp", "pty")

#: Real-time targets run the simulator this many times faster than the wall clock.
SCALE = 4.0


class Target:
    """One way to reach a virtual chain."""

    name: str
    url: str
    virtual: bool = False   # timeouts are virtual seconds (fast in-process)

    def open(self, **options: Any) -> CoolMuscle:
        raise NotImplementedError

    def inject(self, fn: Callable[[Chain], None], after: float = 0.0) -> None:
        """Run ``fn(chain)`` in the model thread, ``after`` virtual seconds from now."""
        raise NotImplementedError

    def close(self) -> None:
        pass


class InProcess(Target):
    name = "inproc"
    virtual = True

    def __init__(self, motors: int = 1) -> None:
        self.url = f"coolmuscle://?mode=fast&motors={motors}"
        self.client: CoolMuscle | None = None

    def open(self, **options: Any) -> CoolMuscle:
        self.client = connect(self.url, **options)
        return self.client

    def inject(self, fn: Callable[[Chain], None], after: float = 0.0) -> None:
        assert self.client is not None, "open a client first: the chain lives in its port"
        chain = self.client.port.chain
        chain.kernel.schedule(seconds(after), lambda: fn(chain), name="test-inject")


class Served(Target):
    """A ServiceThread with a TCP transport (the base of tcp and pty)."""

    def __init__(self, motors: int = 1) -> None:
        self.service = ServiceThread(lambda: Chain(motors=motors),
                                     lambda: [TcpTransport(port=0)], scale=SCALE).start()
        self.port = self.service.transports[0].info()["port"]

    def inject(self, fn: Callable[[Chain], None], after: float = 0.0) -> None:
        def schedule() -> None:
            chain = self.service.chain
            chain.kernel.schedule(seconds(after), lambda: fn(chain), name="test-inject")
        self.service.call(schedule)

    def close(self) -> None:
        self.service.stop()


class Tcp(Served):
    name = "tcp"

    def __init__(self, motors: int = 1) -> None:
        super().__init__(motors)
        self.url = f"socket://127.0.0.1:{self.port}"

    def open(self, **options: Any) -> CoolMuscle:
        return connect(self.url, **options)


class Pty(Served):
    name = "pty"

    def __init__(self, tmp: Path, motors: int = 1) -> None:
        if shutil.which("socat") is None:
            raise RuntimeError("socat is required (scripts/test installs it)")
        super().__init__(motors)
        link = tmp / "cm-pty"
        self.proc = subprocess.Popen(["socat", f"PTY,link={link},raw,echo=0",
                                      f"TCP:127.0.0.1:{self.port}"])
        if not wait_until(link.exists, 5, 0.01):
            self.close()
            raise RuntimeError("socat did not create its pty")
        self.url = str(link.resolve())
        time.sleep(0.05)  # socat connects to the server right after making the pty

    def open(self, **options: Any) -> CoolMuscle:
        return connect(self.url, **options)

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait(5)
        super().close()


def make_target(name: str, tmp: Path, motors: int = 1) -> Target:
    if name == "inproc":
        return InProcess(motors)
    if name == "tcp":
        return Tcp(motors)
    return Pty(tmp, motors)


def target_fixture(name: str, tmp: Path, motors: int = 1) -> Iterator[Target]:
    target = make_target(name, tmp, motors)
    try:
        yield target
    finally:
        target.close()
