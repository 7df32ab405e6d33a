"""``coolmuscle ethercat lab run -- COMMAND``: an EtherCAT lab for one command, root or not.

The command's own process goes into a network namespace of its own (and, without root,
a user namespace of its own where it is root: frontends/ethercat/lab.py
:func:`~coolmuscle.frontends.ethercat.lab.enter_namespace`), makes the veth pair there,
starts ``coolmuscle sim --ethercat SLAVE_IF`` on one end and runs COMMAND, the master,
with the other end in ``$COOLMUSCLE_LAB_MASTER_IF``.  When COMMAND ends the sim is
stopped and the pair removed; the namespace goes with its last process, and both
children are told to end (SIGTERM) should this process die first.  The exit status is
COMMAND's (128 + N when a signal N ended it).

Ctrl-C reaches COMMAND (it is in the terminal's foreground with this process, which
waits for it); SIGTERM and SIGHUP sent to this process are passed on to COMMAND.  The
sim is in a session of its own, stopped once COMMAND has ended.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from types import FrameType

from ...frontends.ethercat import lab as lab_io

__all__ = ["run_lab", "MASTER_VARIABLE", "SLAVE_VARIABLE"]

#: What COMMAND finds in its environment: the master's end, and the slave's.
MASTER_VARIABLE = "COOLMUSCLE_LAB_MASTER_IF"
SLAVE_VARIABLE = "COOLMUSCLE_LAB_SLAVE_IF"
#: Seconds the sim has to print its ready banner, and to stop once asked.
READY_TIMEOUT = 60.0
STOP_TIMEOUT = 10.0
#: prctl(2) option: the signal a child gets when its parent ends.
_PR_SET_PDEATHSIG = 1


def _end_with_parent() -> None:
    """In a child before it runs: SIGTERM when this process ends (the lab goes with it)."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


def run_lab(command: Sequence[str], *, bridge: str = "EB02", sim: bool = True,
            state: Path | None = None, master_if: str = lab_io.DEFAULT_MASTER_IF,
            slave_if: str = lab_io.DEFAULT_SLAVE_IF,
            say: Callable[[str], None] = print) -> int:
    """Run ``command`` as the master of a lab made for it (see the module docstring);
    its exit status.  :class:`~coolmuscle.frontends.ethercat.lab.LabError` when the lab
    cannot be made."""
    if shutil.which(command[0]) is None and not Path(command[0]).exists():
        raise lab_io.LabError(f"no command {command[0]!r} to run in the lab")
    rootless = lab_io.enter_namespace()
    link = lab_io.create_here(lab_io.Lab("", master_if, slave_if))
    where = ("a user and network namespace of its own" if rootless
             else "a network namespace of its own")
    try:
        with _served(link, bridge, state, say) if sim else contextlib.nullcontext():
            say(f"coolmuscle: EtherCAT lab in {where}: the master's end is {master_if} "
                f"(${MASTER_VARIABLE}), the slave's {slave_if}")
            env = {**os.environ, MASTER_VARIABLE: master_if, SLAVE_VARIABLE: slave_if}
            return _run(command, env)
    finally:
        lab_io.destroy_here(link)


@contextlib.contextmanager
def _served(link: lab_io.Lab, bridge: str, state: Path | None,
            say: Callable[[str], None]) -> Iterator[None]:
    """``coolmuscle sim --ethercat`` on the slave's end, ready, and stopped after."""
    logs = Path(tempfile.mkdtemp(prefix="coolmuscle-lab-"))
    log = logs / "sim.log"
    args = [sys.executable, "-m", "coolmuscle", "sim", "--ethercat", link.slave_if,
            "--bridge", bridge, *(["--state", str(state)] if state else ["--no-state"])]
    try:
        with log.open("w") as out:
            proc = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL, start_new_session=True,
                                    preexec_fn=_end_with_parent)
        try:
            for line in _ready(proc, log):
                say(line)
            yield
        finally:
            _stop(proc)
    finally:
        shutil.rmtree(logs, ignore_errors=True)


def _ready(proc: subprocess.Popen[bytes], log: Path) -> list[str]:
    """The sim's banner once it is ready (its lines so far); LabError when it ended."""
    deadline = time.monotonic() + READY_TIMEOUT
    while True:
        ended = proc.poll() is not None
        text = log.read_text(errors="replace")
        match = re.search(r"ready\n.*\n", text)
        if match is not None:
            return text[:match.end()].splitlines()
        if ended or time.monotonic() > deadline:
            raise lab_io.LabError("the bridge did not start in the lab:\n" + text.strip())
        time.sleep(0.05)


def _stop(proc: subprocess.Popen[bytes]) -> None:
    """Stop the sim as a user would (SIGINT), SIGKILL if it does not end."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=STOP_TIMEOUT)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _run(command: Sequence[str], env: dict[str, str]) -> int:
    """COMMAND in the foreground; SIGTERM/SIGHUP passed on, Ctrl-C left to it."""
    proc = subprocess.Popen(list(command), env=env, preexec_fn=_end_with_parent)

    def forward(signum: int, _frame: FrameType | None) -> None:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    old = {sig: signal.signal(sig, handler) for sig, handler in (
        (signal.SIGINT, signal.SIG_IGN), (signal.SIGTERM, forward), (signal.SIGHUP, forward))}
    try:
        code = proc.wait()
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
    return code if code >= 0 else 128 - code
