"""What the test suite shares: chains, served simulators, ports and waiting.

Plain Python (no pytest at import), so bench/ can use it with ``tests/`` on its path;
tests/conftest.py wraps the parts that need a teardown as pytest fixtures
(``make_chain``, ``chain``, ``served_sim``, ``closed_port``).  The machinery is the one
the package ships to its users (:mod:`coolmuscle.testing`, the pytest plug-in's parts);
this module gives it the suite's environment:

* :func:`new_chain` (:func:`coolmuscle.testing.rig.build_chain`) builds a
  :class:`~coolmuscle.chain.daisy.Chain` with the options a test varies (kernel, motors,
  firmware, state directory, machine; a plant load, a few CML lines run first);
  :func:`collect_events` keeps what it says;
* :class:`Program` runs ``coolmuscle ARGS`` as a process whose output goes to a log file
  that is read for its banner; :class:`ServedSim` is ``coolmuscle sim`` on free ports
  (``--tcp 0``, ``--modbus-tcp 0``, a new pty or a pty link, EtherNet/IP, the web page)
  and reads where it serves from its banner, so no test depends on a fixed port being
  free (:mod:`coolmuscle.testing.served`, with :func:`coolmuscle_env`);
* :func:`run_coolmuscle` runs ``coolmuscle ARGS`` to its end, with
  :func:`coolmuscle_env` (this checkout's sources);
* :func:`wait_until` (and :func:`wait_until_async` in a coroutine) polls a condition
  in wall time (a process, a socket, a thread: what virtual time does not drive);
* :func:`free_port` (a port that was free a moment ago, for a program that cannot say
  which port it got) and :func:`closed_port` (a port that refuses connections while the
  ``with`` block lasts).
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from coolmuscle.chain.daisy import Chain
from coolmuscle.device.api import Event
from coolmuscle.testing import served
from coolmuscle.testing.rig import build_chain
from coolmuscle.testing.served import closed_port, free_port, wait_until, wait_until_async

__all__ = ["ROOT", "SRC", "coolmuscle_env", "run_coolmuscle", "wait_until",
           "wait_until_async", "free_port", "closed_port", "new_chain", "ChainFactory",
           "collect_events", "Program", "ServedSim", "SimFactory"]

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


# -- chains ---------------------------------------------------------------------------
#: A chain as the tests build it (``plant``, ``setup``, ``traced``): the plug-in's builder.
new_chain = build_chain


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
class Program(served.Program):
    """:class:`coolmuscle.testing.served.Program` with this checkout's environment
    (:func:`coolmuscle_env`) unless one is given."""

    def __init__(self, args: Sequence[str], log: Path, *, prefix: Sequence[str] = (),
                 env: Mapping[str, str] | None = None, **popen: Any) -> None:
        super().__init__(args, log, prefix=prefix,
                         env=coolmuscle_env() if env is None else env, **popen)


class ServedSim(served.ServedSim):
    """:class:`coolmuscle.testing.served.ServedSim` with this checkout's environment."""

    def __init__(self, log: Path, *args: str, env: Mapping[str, str] | None = None,
                 **options: Any) -> None:
        super().__init__(log, *args, env=coolmuscle_env() if env is None else env, **options)


#: The type of the ``served_sim`` fixture (tests/conftest.py): :class:`ServedSim`'s
#: arguments after the log.
SimFactory = Callable[..., ServedSim]
