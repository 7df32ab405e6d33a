"""What the test suite shares: chains, served simulators, ports and waiting.

Plain Python (no pytest at import), so bench/ can use it with ``tests/`` on its path;
tests/conftest.py wraps the parts that need a teardown as pytest fixtures
(``make_chain``, ``chain``, ``served_sim``, ``closed_port``).

* :func:`new_chain` builds a :class:`~coolmuscle.chain.daisy.Chain` with the options a
  test varies (kernel, motors, firmware, state directory, machine; a plant load, a few
  CML lines run first); :func:`collect_events` keeps what it says;
* :class:`Program` runs ``coolmuscle ARGS`` as a process whose output goes to a log file
  that is read for its banner; :class:`ServedSim` is ``coolmuscle sim`` on free ports
  (``--tcp 0``, ``--modbus-tcp 0``, a new pty or a pty link) and reads where it serves
  from its banner, so no test depends on a fixed port being free;
* :func:`run_coolmuscle` runs ``coolmuscle ARGS`` to its end, with
  :func:`coolmuscle_env` (this checkout's sources);
* :func:`wait_until` (and :func:`wait_until_async` in a coroutine) polls a condition
  in wall time (a process, a socket, a thread: what virtual time does not drive);
* :func:`free_port` (a port that was free a moment ago, for a program that cannot say
  which port it got) and :func:`closed_port` (a port that refuses connections while the
  ``with`` block lasts).
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
from pathlib import Path
from types import TracebackType
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

from coolmuscle.chain.daisy import Chain
from coolmuscle.chain.machine import Machine
from coolmuscle.device.api import Event
from coolmuscle.sim.kernel import Kernel

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"


def coolmuscle_env(**extra: str) -> dict[str, str]:
    """The environment of a ``python -m coolmuscle`` child: this checkout's sources, a
    wide terminal (rich does not wrap one-line errors), no debug tracebacks."""
    env = {**os.environ, "PYTHONPATH": str(SRC), "COLUMNS": "200", **extra}
    env.pop("COOLMUSCLE_DEBUG", None)
    return env


def run_coolmuscle(*args: str, timeout: float = 60, cwd: Path | None = None,
                   env: Mapping[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """``coolmuscle ARGS`` run to its end in a process of its own (stdin closed): exit
    status, stdout and stderr as text."""
    return subprocess.run([sys.executable, "-m", "coolmuscle", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=cwd, stdin=subprocess.DEVNULL,
                          env=dict(env if env is not None else coolmuscle_env()))


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


# -- chains ---------------------------------------------------------------------------
def new_chain(motors: int = 1, firmware: str = "cm2", *, kernel: Kernel | None = None,
              state_dir: Path | str | None = None, machine: Path | str | Machine | None = None,
              pacing: bool = False, plant: Mapping[str, float] | None = None,
              traced: bool = False, setup: str | Iterable[str] = ()) -> Chain:
    """A chain as the tests build it: ``plant`` sets fields of every motor's plant (a
    load, friction: motor/motion/plant.py), each line of ``setup`` runs as CML, then
    ``traced`` starts its trace recorder (``record(chain)`` gives it back)."""
    chain = Chain(kernel, motors, firmware=firmware, state_dir=state_dir, machine=machine,
                  pacing=pacing)
    for motor in chain.motors.values():
        for name, value in (plant or {}).items():
            setattr(motor.plant, name, value)
    for line in [setup] if isinstance(setup, str) else setup:
        chain.execute(line)
    if traced:
        from coolmuscle.tools.trace.recorder import record
        record(chain)
    return chain


#: The type of the ``make_chain`` fixture (tests/conftest.py): :func:`new_chain`'s arguments.
ChainFactory = Callable[..., Chain]


def collect_events(chain: Chain, kinds: Sequence[str] | None = None) -> list[Event]:
    """The list the chain's events are appended to from now on (only ``kinds`` when
    given: "status", "alarm", "message", "reply", ...)."""
    events: list[Event] = []
    if kinds is None:
        chain.subscribe(events.append)
    else:
        wanted = frozenset(kinds)
        chain.subscribe(lambda event: events.append(event) if event.kind in wanted else None)
    return events


# -- coolmuscle as a process ----------------------------------------------------------------
class Program:
    """``coolmuscle ARGS`` as a process in a session of its own; stdout and stderr go to
    ``log``, which :meth:`wait_for` reads.  :meth:`close` ends the whole process group
    (SIGKILL if it is still running): nothing is left behind."""

    def __init__(self, args: Sequence[str], log: Path, *, prefix: Sequence[str] = (),
                 env: Mapping[str, str] | None = None, **popen: Any) -> None:
        self.args = list(args)
        self.log = log
        with log.open("w") as out:
            self.proc: subprocess.Popen[bytes] = subprocess.Popen(
                [*prefix, sys.executable, "-m", "coolmuscle", *self.args], stdout=out,
                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                env=dict(env if env is not None else coolmuscle_env()),
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
        """Kill its process group if anything of it still runs, and reap it."""
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(timeout=10)
        else:
            with contextlib.suppress(ProcessLookupError):      # a child it left behind
                os.killpg(self.proc.pid, signal.SIGKILL)

    kill = close

    def __enter__(self) -> "Program":
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class ServedSim(Program):
    """``coolmuscle sim ARGS`` on free ports, started and ready (its banner printed).

    ``tcp``: ``--tcp 0`` (:attr:`port`, :attr:`url`); ``modbus_tcp``: ``--modbus-tcp 0``
    (:attr:`modbus_port`); ``pty``: ``True`` for ``--pty`` or a path for ``--pty-link``
    (:attr:`pty`: the device, or the link); ``state``: ``--state DIR``, else
    ``--no-state``.  :attr:`served` holds every banner item (``{"tcp":
    "127.0.0.1:40123", ...}``)."""

    def __init__(self, log: Path, *args: str, tcp: bool = True, modbus_tcp: bool = False,
                 pty: bool | Path = False, state: Path | None = None,
                 prefix: Sequence[str] = (), env: Mapping[str, str] | None = None,
                 ready_timeout: float = 30) -> None:
        argv = ["sim", *(["--tcp", "0"] if tcp else []),
                *(["--modbus-tcp", "0"] if modbus_tcp else []),
                *(["--pty"] if pty is True else []),
                *(["--pty-link", str(pty)] if isinstance(pty, Path) else []),
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

    def _port(self, name: str) -> int:
        if name not in self.served:
            raise AssertionError(f"the sim serves no {name}: {self.banner}")
        return int(self.served[name].split()[0].rsplit(":", 1)[1])

    @property
    def port(self) -> int:
        """The TCP port of the CML text line."""
        return self._port("tcp")

    @property
    def url(self) -> str:
        """The pyserial URL of the TCP line (``socket://127.0.0.1:PORT``)."""
        return f"socket://127.0.0.1:{self.port}"

    @property
    def modbus_port(self) -> int:
        return self._port("modbus-tcp")

    @property
    def pty(self) -> str:
        """The pty's device, or its link with ``pty=PATH``."""
        if "pty" not in self.served:
            raise AssertionError(f"the sim serves no pty: {self.banner}")
        return self.served["pty"].split(" -> ")[0]

    def stop(self, signum: int = signal.SIGINT, timeout: float = 20) -> int:
        """A stop signal, as a user would send it; the exit status."""
        return self.signal(signum, timeout)


#: The type of the ``served_sim`` fixture (tests/conftest.py): :class:`ServedSim`'s
#: arguments after the log.
SimFactory = Callable[..., ServedSim]
