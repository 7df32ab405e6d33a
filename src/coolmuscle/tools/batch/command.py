"""``coolmuscle batch``: many scripts / golden transcripts side by side (docs/batch.md).

Each script runs on a fresh chain in fast virtual time with the ``coolmuscle run``
runner (docs/scripts.md): one with ``<<`` expectations is checked as ``run --check``
checks it, one without just runs.  The runs go to a local process pool (``--jobs``,
default the CPU count) or a Dask cluster (``--scheduler``); a progress bar while they
run, a summary table at the end, JUnit XML (``--junit``) and a results table
(``--results``).  Exit status 0 when every run passed, 1 when one failed, 2 for bad
input (found before anything runs), 130 after a Ctrl-C (what finished is reported and
written).
"""

from __future__ import annotations

import logging
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from ..cli.host_commands import FirmwareChoice
from ..cli.usage import UsageError
from .engine import Engine, EngineError, open_engine
from .figures import ns_to_seconds
from .job import FIRMWARES, Job, JobError, Outcome, make_job
from .report import ReportError, check_output, write_junit, write_results

log = logging.getLogger(__name__)

EXIT_FAILED = 1
EXIT_INTERRUPTED = 130

err = Console(stderr=True, soft_wrap=True, highlight=False)

JOBS_HELP = "Runs at once on this machine (default: the CPU count)."
SCHEDULER_HELP = ("Send the runs to this Dask scheduler (tcp://HOST:8786) instead of "
                  "local processes.")
MOTORS_HELP = "Motors on each chain (a script's '# chain: motors=N' header wins)."
FIRMWARE_HELP = "Firmware profile: cm2, rt3 or cm1 (a '# chain: firmware=' header wins)."
UNTIL_HELP = "After each script, run on to this virtual time (seconds)."


def usage_error(message: str) -> Exception:
    """The command's exit-2 error (:class:`coolmuscle.tools.cli.usage.UsageError`)."""
    return UsageError(message)


@dataclass
class BatchRun:
    """The outcomes of a batch (job order; ``None`` = not finished) and how it ended."""

    jobs: list[Job]
    outcomes: list[Outcome | None]
    interrupted: bool
    wall_s: float
    engine: str
    stopped: str = ""  # why the engine stopped before the end (a worker died), if it did

    @property
    def done(self) -> list[Outcome]:
        return [o for o in self.outcomes if o is not None]

    @property
    def failed(self) -> list[Outcome]:
        return [o for o in self.done if not o.ok]

    def exit_code(self) -> int:
        if self.interrupted:
            return EXIT_INTERRUPTED
        return EXIT_FAILED if self.failed or self.stopped else 0


def script_paths(scripts: Sequence[Path]) -> list[Path]:
    """The files to run: each path given, a directory standing for its ``*.cml``."""
    paths: list[Path] = []
    for path in scripts:
        if path.is_dir():
            found = sorted(path.glob("*.cml"))
            if not found:
                raise usage_error(f"{path}: directory has no .cml scripts")
            paths += found
        elif path.is_file():
            paths.append(path)
        elif path.exists():
            raise usage_error(f"{path}: not a regular file")
        else:
            raise usage_error(f"{path}: no such script")
    return paths


def read_text(path: Path, what: str = "script") -> str:
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise usage_error(f"cannot read {what} {path}: "
                          f"{getattr(exc, 'strerror', None) or exc}") from None


def check_options(motors: int, firmware: str, until: float | None) -> None:
    if not 1 <= motors <= 15:
        raise usage_error(f"--motors must be 1..15, not {motors}")
    if firmware not in FIRMWARES:
        raise usage_error(f"--firmware must be cm2, rt3 or cm1, not {firmware!r}")
    if until is not None:
        from ..cli.run import MAX_UNTIL_S
        if not (math.isfinite(until) and 0 <= until <= MAX_UNTIL_S):
            raise usage_error(f"--until must be 0..{MAX_UNTIL_S:g} seconds, not {until!r}")


def prepare(build: Callable[[], list[Job]]) -> list[Job]:
    """Build the jobs, turning a bad script / header / machine file into exit 2."""
    try:
        return build()
    except JobError as exc:
        raise usage_error(str(exc)) from None


def start_engine(jobs: int | None, scheduler: str | None, runs: int) -> Engine:
    try:
        return open_engine(jobs, scheduler, runs)
    except EngineError as exc:
        raise usage_error(str(exc)) from None


def check_outputs(**paths: Path | None) -> None:
    """``check_outputs(junit=..., results=...)``: each writable, before anything runs."""
    for option, path in paths.items():
        if path is not None:
            try:
                check_output(path, f"--{option}", parquet_ok=option == "results")
            except ReportError as exc:
                raise usage_error(str(exc)) from None


def run_all(engine: Engine, jobs: list[Job], label: str = "runs") -> BatchRun:
    """Run every job with a progress bar; a Ctrl-C stops them and keeps what finished."""
    outcomes: list[Outcome | None] = [None] * len(jobs)
    counts = {"failed": 0}
    start = time.perf_counter()
    interrupted = False
    stopped = ""
    progress = Progress(TextColumn("[bold]{task.description}"), BarColumn(),
                        MofNCompleteColumn(), TextColumn("{task.fields[failed]} failed"),
                        TimeElapsedColumn(), console=err, transient=False)
    with progress:
        task = progress.add_task(label, total=len(jobs), failed=0)

        def done(index: int, outcome: Outcome) -> None:
            outcomes[index] = outcome
            if not outcome.ok:
                counts["failed"] += 1
            progress.update(task, advance=1, failed=counts["failed"])

        try:
            engine.run(jobs, done)
        except KeyboardInterrupt:
            interrupted = True
        except Exception as exc:  # the engine broke (a worker died): report what finished
            log.debug("the engine failed", exc_info=True)
            stopped = f"the runs stopped: {type(exc).__name__}: {exc}"
        finally:
            try:
                engine.close()
            except KeyboardInterrupt:
                interrupted = True
    return BatchRun(jobs, outcomes, interrupted, time.perf_counter() - start,
                    engine.description, stopped)


def _result_text(outcome: Outcome | None) -> str:
    if outcome is None:
        return "[yellow]not run[/]"
    return {"pass": "[green]pass[/]", "ran": "[green]ran[/]", "fail": "[red]FAIL[/]",
            "error": "[red]ERROR[/]"}[outcome.status]


def print_summary(run: BatchRun, value_names: Sequence[str] = (),
                  figures: Sequence[str] = ()) -> None:
    """The summary table (stdout), each failure's first difference and a count (stderr).

    A sweep's table shows the varied values instead of the script's name."""
    probe = Console()
    out = Console(highlight=False, width=probe.width if probe.is_terminal else 200)
    table = Table(box=None, pad_edge=False)
    for name in value_names:
        table.add_column(name, overflow="fold")
    if not value_names:
        longest = max((len(job.name) for job in run.jobs), default=6)
        table.add_column("script", overflow="fold", min_width=min(longest, 40))
    table.add_column("result", no_wrap=True)
    table.add_column("virtual s", justify="right", no_wrap=True)
    for figure in figures:
        table.add_column(figure, justify="right", no_wrap=True)
    table.add_column("first difference", overflow="fold")
    for job, outcome in zip(run.jobs, run.outcomes):
        values = dict(job.values)
        cells = [_escape(values.get(n, "")) for n in value_names] or [_escape(job.name)]
        cells += [_result_text(outcome), ns_to_seconds(outcome.end_ns) if outcome else ""]
        shown = dict(outcome.figures) if outcome else {}
        cells += [_short_number(shown.get(f, "")) for f in figures]
        cells.append(_escape(outcome.message if outcome else ""))
        table.add_row(*cells)
    out.print(table)
    for outcome in run.failed:
        err.print(f"coolmuscle: FAIL {outcome.name}: {outcome.message}", markup=False)
    done = run.done
    passed = sum(o.ok for o in done)
    errors = sum(o.status == "error" for o in done)
    failed = len(done) - passed - errors
    text = (f"coolmuscle: {len(run.jobs)} run(s): {passed} passed, {failed} failed, "
            f"{errors} error(s) in {run.wall_s:.2f} s on {run.engine}")
    if run.interrupted or run.stopped:
        text += (f"; {'interrupted' if run.interrupted else 'stopped'}: {len(done)} "
                 f"finished, {len(run.jobs) - len(done)} not run")
    err.print(text, markup=False)
    if run.stopped:
        err.print(f"coolmuscle: error: {run.stopped}", markup=False)


def _short_number(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _escape(text: object) -> str:
    from rich.markup import escape  # noqa: PLC0415
    return escape(str(text))


def write_outputs(run: BatchRun, junit: Path | None, results: Path | None,
                  suite: str) -> None:
    def junit_to(p: Path) -> None:
        write_junit(p, run.jobs, run.outcomes, suite=suite)

    def results_to(p: Path) -> None:
        write_results(p, run.jobs, run.outcomes)
    writers: tuple[tuple[Path | None, Callable[[Path], None]], ...] = (
        (junit, junit_to), (results, results_to))
    for path, write in writers:
        if path is None:
            continue
        try:
            write(path)
        except OSError as exc:    # a full disk fails at close: exc.filename is None there
            raise usage_error(f"cannot write {exc.filename or path}: "
                              f"{exc.strerror or exc}") from None


def batch(
    scripts: list[Path] = typer.Argument(..., metavar="SCRIPTS...",
                                         help="Scripts / golden transcripts, or "
                                              "directories of *.cml."),
    jobs: int | None = typer.Option(None, "--jobs", "-j", metavar="N", help=JOBS_HELP),
    scheduler: str | None = typer.Option(None, "--scheduler", metavar="tcp://HOST:8786",
                                            help=SCHEDULER_HELP),
    junit: Path | None = typer.Option(None, "--junit", metavar="FILE.xml",
                                         help="Write JUnit XML: one testcase per script."),
    results: Path | None = typer.Option(
        None, "--results", metavar="FILE.csv",
        help="Write one row per script with the run's figures: CSV, or Parquet for "
             "FILE.parquet (needs pyarrow)."),
    motors: int = typer.Option(1, "--motors", min=1, max=15, help=MOTORS_HELP),
    firmware_choice: FirmwareChoice = typer.Option(FirmwareChoice.cm2, "--firmware",
                                                   help=FIRMWARE_HELP),
    until: float | None = typer.Option(None, "--until", metavar="SECONDS",
                                          help=UNTIL_HELP),
    machine: Path | None = typer.Option(None, "--machine", metavar="AXIS.toml",
                                           help="Machine file for every script without "
                                                "a '# chain: machine=' header."),
) -> None:
    """Run many scripts side by side and report pass/fail per script, like a test runner."""
    firmware = firmware_choice.value
    check_options(motors, firmware, until)
    paths = script_paths(scripts)
    machine_text = (str(machine), read_text(machine, "machine file")) if machine else None
    texts = [(path, read_text(path)) for path in paths]
    built = prepare(lambda: [make_job(str(path), text, path.parent, motors=motors,
                                      firmware=firmware, until=until, machine=machine_text,
                                      figures=results is not None)
                             for path, text in texts])
    check_outputs(junit=junit, results=results)
    engine = start_engine(jobs, scheduler, len(built))
    run = run_all(engine, built, "batch")
    write_outputs(run, junit, results, "coolmuscle.batch")
    print_summary(run)
    sys.stdout.flush()
    if run.exit_code():
        raise typer.Exit(run.exit_code())
