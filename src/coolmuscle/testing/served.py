"""``coolmuscle`` as a process for a test: started on free ports, ready, and gone after.

* :class:`Program` runs ``python -m coolmuscle ARGS`` in a session of its own, its output
  to a log file that :meth:`Program.wait_for` reads; :meth:`Program.close` ends its whole
  process group, so nothing it started is left behind;
* :class:`ServedSim` is ``coolmuscle sim`` on free ports, any front door: the CML text
  line on TCP (``--tcp 0``), a pty or an RFC 2217 port (``--rfc2217 0``), Modbus TCP
  (``--modbus-tcp 0``), the CM1 EtherNet/IP module (``--enip 127.0.0.1:0
  --enip-io-port 0``), the web dashboard (``--web 0``); it reads where each is served
  from the banner, so no test depends on a fixed port being free (docs/transports.md);
* :func:`wait_until` (and :func:`wait_until_async`) polls a condition in wall time,
  :func:`free_port` and :func:`closed_port` give ports for programs that cannot say
  which port they got.

The child runs the same ``coolmuscle`` as the parent (the folder this package was
imported from leads its ``PYTHONPATH``), with a wide terminal so the banner is one line.
Standard library only: the test plug-in (:mod:`.plugin`) and coolmuscle's own suite
(tests/fixtures.py) both use it.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

__all__ = ["Program", "ServedSim", "child_env", "wait_until", "wait_until_async",
           "free_port", "closed_port", "PACKAGE_ROOT"]

#: The folder holding the ``coolmuscle`` package the parent imported.
PACKAGE_ROOT = Path(__file__).resolve().parents[2]


def child_env(base: Mapping[str, str] | None = None, **extra: str) -> dict[str, str]:
    """The environment of a ``python -m coolmuscle`` child: ``base`` (this process's by
    default) with :data:`PACKAGE_ROOT` first on ``PYTHONPATH``, a wide terminal (rich
    does not wrap the banner) and ``extra``."""
    env = dict(os.environ if base is None else base)
    paths = [str(PACKAGE_ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep)
                                   if p and p != str(PACKAGE_ROOT)]
    env.update(PYTHONPATH=os.pathsep.join(paths), COLUMNS="400", **extra)
    return env


# -- waiting --------------------------------------------------------------------------
def wait_until(predicate: Callable[[], object], timeout: float = 5.0,
               step: float = 0.02) -> bool:
    """Poll ``predicate`` every ``step`` seconds until it is true or ``timeout`` seconds
    passed; whether it became true (a last try at the deadline counts)."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            return bool(predicate())
        time.sleep(step)
    return True


async def wait_until_async(predicate: Callable[[], object], timeout: float = 5.0,
                           step: float = 0.01) -> bool:
    """:func:`wait_until` inside a coroutine: the event loop runs while it waits."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            return bool(predicate())
        await asyncio.sleep(step)
    return True


# -- ports ------------------------------------------------------------------------------
def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nobody listened on a moment ago.  Another process may take it before
    it is used: give a server port 0 and read the port it got wherever it can say it."""
    with socket.socket() as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


@contextlib.contextmanager
def closed_port(host: str = "127.0.0.1") -> Iterator[int]:
    """A TCP port that refuses connections for as long as the block lasts: bound by this
    process and not listening (the kernel answers a SYN with RST), so no other program
    can start listening on it meanwhile."""
    with socket.socket() as sock:
        sock.bind((host, 0))
        yield int(sock.getsockname()[1])


# -- coolmuscle as a process ----------------------------------------------------------------
class Program:
    """``coolmuscle ARGS`` as a process in a session of its own; stdout and stderr go to
    ``log``, which :meth:`wait_for` reads.  :meth:`close` ends the whole process group
    (SIGKILL if it is still running): nothing is left behind.  ``prefix`` runs it through
    another command (``ip netns exec NS``)."""

    def __init__(self, args: Sequence[str], log: Path, *, prefix: Sequence[str] = (),
                 env: Mapping[str, str] | None = None, **popen: Any) -> None:
        self.args = list(args)
        self.log = log
        with log.open("w") as out:
            self.proc: subprocess.Popen[bytes] = subprocess.Popen(
                [*prefix, sys.executable, "-m", "coolmuscle", *self.args], stdout=out,
                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                env=dict(env if env is not None else child_env()),
                start_new_session=True, **popen)

    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def text(self) -> str:
        """What it printed so far."""
        return self.log.read_text(errors="replace")

    def wait_for(self, pattern: str, timeout: float = 30) -> re.Match[str]:
        """The first match of ``pattern`` in its output; an AssertionError (with the
        output) when it ended or ``timeout`` passed first."""
        deadline = time.monotonic() + timeout
        while True:
            ended = self.proc.poll() is not None        # before the read: its last words
            match = re.search(pattern, self.text)
            if match is not None:
                return match
            if ended or time.monotonic() > deadline:
                raise AssertionError(f"coolmuscle {' '.join(self.args)}: {pattern!r} not "
                                     f"printed (exit {self.proc.poll()}):\n{self.text}")
            time.sleep(0.05)

    def signal(self, signum: int = signal.SIGINT, timeout: float = 20) -> int:
        """Send ``signum`` (if it still runs) and wait for the end: the exit status."""
        if self.proc.poll() is None:
            self.proc.send_signal(signum)
        return self.proc.wait(timeout=timeout)

    def close(self) -> None:
        """Kill its process group if anything of it still runs, and reap it (where
        there are no process groups, Windows: the process)."""
        killpg = getattr(os, "killpg", None)
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                if killpg is not None:
                    killpg(self.proc.pid, signal.SIGKILL)
                else:
                    self.proc.kill()
            self.proc.wait(timeout=10)
        elif killpg is not None:
            with contextlib.suppress(ProcessLookupError):      # a child it left behind
                killpg(self.proc.pid, signal.SIGKILL)

    kill = close

    def __enter__(self) -> Program:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class ServedSim(Program):
    """``coolmuscle sim ARGS`` on free ports, started and ready (its banner printed).

    ``tcp``: ``--tcp 0`` (:attr:`port`, :attr:`url`); ``modbus_tcp``: ``--modbus-tcp 0``
    (:attr:`modbus_port`); ``rfc2217``: ``--rfc2217 0`` (:attr:`rfc2217_url`); ``pty``:
    ``True`` for ``--pty`` or a path for ``--pty-link`` (:attr:`pty`: the device, or the
    link); ``enip``: the CM1 EtherNet/IP module on free TCP and UDP ports
    (:attr:`enip_port`, :attr:`enip_io_port`; the chain must be CM1, ``--firmware cm1``);
    ``web``: the dashboard (:attr:`web_url`, :attr:`web_port`); ``state``: ``--state
    DIR``, else ``--no-state``.  :attr:`served` holds every banner
    item (``{"tcp": "127.0.0.1:40123", ...}``)."""

    def __init__(self, log: Path, *args: str, tcp: bool = True, modbus_tcp: bool = False,
                 pty: bool | Path = False, enip: bool = False, web: bool = False,
                 state: Path | None = None, prefix: Sequence[str] = (),
                 env: Mapping[str, str] | None = None, ready_timeout: float = 30,
                 rfc2217: bool = False) -> None:
        argv = ["sim", *(["--tcp", "0"] if tcp else []),
                *(["--modbus-tcp", "0"] if modbus_tcp else []),
                *(["--rfc2217", "0"] if rfc2217 else []),
                *(["--pty"] if pty is True else []),
                *(["--pty-link", str(pty)] if isinstance(pty, Path) else []),
                *(["--enip", "127.0.0.1:0", "--enip-io-port", "0"] if enip else []),
                *(["--web", "0"] if web else []),
                *(["--state", str(state)] if state is not None else ["--no-state"]), *args]
        super().__init__(argv, log, prefix=prefix, env=env)
        try:
            self.banner = self.wait_for(r"coolmuscle: .* ready\n(.*\(state: .*\))\n",
                                        ready_timeout).group(1)
        except BaseException:
            self.close()
            raise
        self.served = dict(item.split(": ", 1) for item in self.banner.split("   ")
                           if not item.startswith("(state: "))

    def _item(self, name: str) -> str:
        if name not in self.served:
            raise AssertionError(f"the sim serves no {name}: {self.banner}")
        return self.served[name]

    def _port(self, name: str) -> int:
        return int(self._item(name).split()[0].rstrip("/").rsplit(":", 1)[1])

    @property
    def port(self) -> int:
        """The TCP port of the CML text line."""
        return self._port("tcp")

    @property
    def url(self) -> str:
        """The pyserial URL of the TCP line (``socket://127.0.0.1:PORT``)."""
        return f"socket://127.0.0.1:{self.port}"

    @property
    def rfc2217_url(self) -> str:
        """The pyserial URL of the RFC 2217 port (``rfc2217://127.0.0.1:PORT``)."""
        return f"rfc2217://127.0.0.1:{self._port('rfc2217')}"

    @property
    def modbus_port(self) -> int:
        return self._port("modbus-tcp")

    @property
    def enip_port(self) -> int:
        """The EtherNet/IP encapsulation port (TCP, and UDP for List Identity)."""
        return self._port("enip")

    @property
    def enip_io_port(self) -> int:
        """The UDP port of Class 1 I/O (``(I/O udp PORT)`` in the banner)."""
        match = re.search(r"I/O udp (\d+)", self._item("enip"))
        if match is None:
            raise AssertionError(f"no Class 1 I/O port in the banner: {self.banner}")
        return int(match.group(1))

    @property
    def web_url(self) -> str:
        """The dashboard's address (``http://127.0.0.1:PORT/``)."""
        return self._item("web").split()[0]

    @property
    def web_port(self) -> int:
        return self._port("web")

    @property
    def ports(self) -> list[tuple[str, int]]:
        """Every (protocol, port) it serves on: what must be closed once it is gone."""
        found: list[tuple[str, int]] = []
        for name, text in self.served.items():
            match = re.match(r"(?:http://)?[\w.:\[\]-]*?:(\d+)", text)
            if name in ("tcp", "modbus-tcp", "rfc2217", "web", "enip") and match:
                found.append(("tcp", int(match.group(1))))
            if name == "enip":
                found.append(("udp", self.enip_io_port))
        return found

    @property
    def pty(self) -> str:
        """The pty's device, or its link with ``pty=PATH``."""
        return self._item("pty").split(" -> ")[0]

    def stop(self, signum: int = signal.SIGINT, timeout: float = 20) -> int:
        """A stop signal, as a user would send it; the exit status."""
        return self.signal(signum, timeout)


#: The type of a factory of served sims (``served_sim`` in coolmuscle's suite,
#: ``cm_sim_factory`` of the plug-in): :class:`ServedSim`'s arguments after the log.
SimFactory = Callable[..., ServedSim]
