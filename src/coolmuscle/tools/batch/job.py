"""One run of a batch or a sweep: what is sent to a worker and what comes back.

A :class:`Job` carries the script *text* (and the machine file's text), never a path,
so a Dask worker on another machine needs nothing but coolmuscle installed.
:func:`execute` runs it with the ``coolmuscle run`` runner (:func:`coolmuscle.script.
run_script`) on a fresh chain in fast virtual time and returns an :class:`Outcome` made
of plain values only: the same job gives the same outcome, bit for bit, in any process
on any machine (the run is deterministic; only ``wall_s`` differs).

A script may choose its chain in a header comment, as the golden transcripts do
(tests/transcripts, docs/machine-file.md): ``# chain: motors=3 firmware=rt3
machine=machines/slide.toml state=1`` (the machine file relative to the script; ``state``
gives the run a fresh state directory of its own).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import re
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from ...chain.machine import MachineFileError, parse_machine
from ...errors import CoolMuscleError
from ..script.runner import ScriptError, parse_script, run_script
from .figures import FigureProbe

log = logging.getLogger(__name__)

Status = Literal["pass", "fail", "ran", "error"]

#: The script header: ``# chain:`` (golden transcripts) or ``# coolmuscle:`` (what
#: ``coolmuscle run`` reads, docs/scripts.md); both are read, in file order.
_HEADER = re.compile(r"^# (?:chain|coolmuscle):(.*)$", re.MULTILINE | re.IGNORECASE)
_HEADER_KEYS = ("motors", "firmware", "machine", "state")
FIRMWARES = ("cm2", "rt3", "cm1")


class JobError(CoolMuscleError, ValueError):
    """A script, header or machine file that cannot make a job (exit status 2)."""


@dataclass(frozen=True)
class Job:
    """Everything one run needs, as plain picklable values."""

    name: str
    script: str
    machine: str | None = None
    machine_name: str = "<machine>"
    motors: int = 1
    firmware: str = "cm2"
    until: float | None = None
    state: bool = False
    values: tuple[tuple[str, str], ...] = ()
    figures: bool = False


@dataclass(frozen=True)
class Outcome:
    """What a run gave; equal outcomes are equal runs (``wall_s`` is not compared)."""

    name: str
    status: Status
    message: str
    expectations: int
    matched: int
    end_ns: int
    kind: str = ""   # the failure's kind: mismatch, unexpected, timeout, error
    values: tuple[tuple[str, str], ...] = ()
    figures: tuple[tuple[str, object], ...] = ()
    wall_s: float = field(default=0.0, compare=False)

    @property
    def ok(self) -> bool:
        return self.status in ("pass", "ran")


def chain_header(text: str) -> dict[str, str]:
    """``# chain: motors=3 firmware=rt3`` -> ``{"motors": "3", "firmware": "rt3"}``
    (``# coolmuscle: motors=3`` alike; a later header line adds to or overrides an
    earlier one)."""
    options: dict[str, str] = {}
    for match in _HEADER.finditer(text):
        for item in match.group(1).split():
            key, _, value = item.partition("=")
            options[key.lower()] = value
    return options


def make_job(name: str, text: str, where: Path | None, *, motors: int = 1,
             firmware: str = "cm2", until: float | None = None,
             machine: tuple[str, str] | None = None, figures: bool = False,
             values: tuple[tuple[str, str], ...] = ()) -> Job:
    """A checked job: the script parses, the header and the machine file are valid.

    ``where`` is the script's directory (for a header's ``machine=``); ``machine`` is
    ``(name, text)`` of a machine file given on the command line.  The header of the
    script wins over the command-line defaults.  Raises :class:`JobError`.
    """
    try:
        parse_script(text)
    except ScriptError as exc:
        raise JobError(f"{name}: {exc}") from None
    header = chain_header(text)
    unknown = sorted(set(header) - set(_HEADER_KEYS))
    if unknown:
        raise JobError(f"{name}: unknown '# chain:' key {unknown[0]!r} "
                       f"(known: {', '.join(_HEADER_KEYS)})")
    if "motors" in header:
        if not header["motors"].isdigit():
            raise JobError(f"{name}: '# chain: motors=' needs a number 1..15")
        motors = int(header["motors"])
    if not 1 <= motors <= 15:
        raise JobError(f"{name}: a chain has 1 to 15 motors, not {motors}")
    firmware = header.get("firmware", firmware)
    if firmware not in FIRMWARES:
        raise JobError(f"{name}: unknown firmware {firmware!r} (cm2, rt3 or cm1)")
    if "machine" in header:
        path = (where or Path(".")) / header["machine"]
        try:
            machine = (str(path), path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError) as exc:
            raise JobError(f"{name}: cannot read machine file {path}: "
                           f"{getattr(exc, 'strerror', None) or exc}") from None
    if machine is not None:
        try:
            parse_machine(machine[1], machine[0])
        except MachineFileError as exc:
            raise JobError(f"{name}: {exc}") from None
    return Job(name=name, script=text, machine=None if machine is None else machine[1],
               machine_name="<machine>" if machine is None else machine[0],
               motors=motors, firmware=firmware, until=until,
               state=header.get("state", "0") not in ("", "0"), values=values,
               figures=figures)


def execute(job: Job) -> Outcome:
    """Run ``job`` on a fresh chain; never raises for a failing or broken run."""
    start = time.perf_counter()
    state: Any = (tempfile.TemporaryDirectory(prefix="coolmuscle-batch-") if job.state
                  else contextlib.nullcontext())
    with state as state_dir:
        try:
            outcome = _run(job, state_dir)
        except Exception as exc:  # a model or setup bug: this run's error, not the batch's
            log.debug("job %s raised", job.name, exc_info=True)
            outcome = Outcome(name=job.name, status="error", kind="error",
                              message=f"{type(exc).__name__}: {exc}", expectations=0,
                              matched=0, end_ns=0, values=job.values)
    return dataclasses.replace(outcome, wall_s=time.perf_counter() - start)


def execute_many(jobs: list[Job]) -> list[Outcome]:
    """:func:`execute` each job in turn (one worker task for several short runs)."""
    return [execute(job) for job in jobs]


def _run(job: Job, state_dir: str | None) -> Outcome:
    from ...chain import Chain

    script = parse_script(job.script)
    machine = None if job.machine is None else parse_machine(job.machine, job.machine_name)
    chain = Chain(None, job.motors, firmware=job.firmware, state_dir=state_dir,
                  machine=machine)
    try:
        probe = FigureProbe(chain) if job.figures else None
        result = run_script(script, chain, until=job.until)
        figures = tuple(probe.figures().items()) if probe is not None else ()
    finally:
        chain.close()
    status: Status = "pass" if script.expectations else "ran"
    kind = message = ""
    if result.failure is not None:
        kind, message = result.failure.kind, result.failure.message
        status = "error" if kind == "error" else "fail"
    return Outcome(name=job.name, status=status, message=message,
                   expectations=result.expectations, matched=result.matched,
                   end_ns=result.end_time, kind=kind, values=job.values, figures=figures)
