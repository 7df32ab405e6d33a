"""``coolmuscle sweep``: one script run for every combination of ``--vary`` values.

``{NAME}`` in the script (and in the ``--machine`` file) is replaced by each value of
``--vary NAME=V1,V2,...``; with several ``--vary`` every combination runs (the first
``--vary`` varies slowest).  Each run is a batch job (:mod:`coolmuscle.tools.batch.job`)
with its figures; the results table has one row per run (docs/batch.md) and ``--plot``
draws one figure against the varied values.  Placeholders are ``{`` + a name + ``}``
only, so regular-expression counts such as ``\\d{3}`` in an ``@until`` stay as they are.
"""

from __future__ import annotations

import itertools
import logging
import math
import re
import sys
from pathlib import Path

import typer

from ...cml.parser import parse
from ...errors import CmlSyntaxError
from ..cli.host_commands import FirmwareChoice
from ..script.runner import ScriptError, parse_line
from .command import (
    FIRMWARE_HELP,
    JOBS_HELP,
    MOTORS_HELP,
    SCHEDULER_HELP,
    UNTIL_HELP,
    check_options,
    check_outputs,
    prepare,
    print_summary,
    read_text,
    run_all,
    script_paths,
    start_engine,
    usage_error,
    write_outputs,
)
from .figures import FIGURES
from .job import Job, make_job

log = logging.getLogger(__name__)

PLACEHOLDER = re.compile(r"\{([A-Za-z_][A-Za-z0-9_]*)\}")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*$")

#: Figures ``--figure`` can plot (numbers); the others (in_position, alarms) are text.
NUMERIC = ("final_position", "peak_speed", "peak_torque", "peak_temperature")
PLOT_SUFFIXES = (".png", ".svg", ".pdf")

#: Most runs one sweep makes (a bigger grid is an error, before anything runs).
MAX_RUNS = 100_000


def parse_vary(items: list[str]) -> list[tuple[str, list[str]]]:
    """``["S=100,200", "K=1,2"]`` -> ``[("S", ["100", "200"]), ("K", ["1", "2"])]``."""
    out: list[tuple[str, list[str]]] = []
    for item in items:
        name, sep, values = item.partition("=")
        name = name.strip()
        if not sep or not _NAME.match(name):
            raise usage_error(f"--vary {item!r}: write NAME=V1,V2,... (NAME: letters, "
                              "digits, _)")
        if any(name == n for n, _ in out):
            raise usage_error(f"--vary {name} is given twice")
        choices = [v.strip() for v in values.split(",")]
        if not values.strip() or any(not v for v in choices):
            raise usage_error(f"--vary {name}: empty value in {values!r}")
        out.append((name, choices))
    return out


def placeholders(text: str) -> list[str]:
    """Names of the ``{NAME}`` placeholders, in order of first appearance."""
    seen: list[str] = []
    for name in PLACEHOLDER.findall(text):
        if name not in seen:
            seen.append(name)
    return seen


def substitute(text: str, values: dict[str, str]) -> str:
    return PLACEHOLDER.sub(lambda m: values.get(m.group(1), m.group(0)), text)


def figure_column(figure: str, motors: int) -> str:
    """``peak_speed`` -> ``m1.peak_speed``; ``m2.peak_torque`` as is; checked."""
    if figure == "duration_s":
        return figure
    motor, _, name = figure.rpartition(".")
    motor = motor or "m1"
    if name not in NUMERIC:
        other = " (it is text)" if name in FIGURES else ""
        raise usage_error(f"--figure {figure}{other}: choose one of {', '.join(NUMERIC)}, "
                          "duration_s (m<ID>. in front for another motor)")
    if not re.fullmatch(r"m(\d+)", motor) or not 1 <= int(motor[1:]) <= motors:
        raise usage_error(f"--figure {figure}: motor prefix must be m1..m{motors}")
    return f"{motor}.{name}"


def build_jobs(script: Path, text: str, machine: tuple[str, str] | None,
               vary: list[tuple[str, list[str]]], motors: int, firmware: str,
               until: float | None) -> list[Job]:
    """Every combination as a checked job; a placeholder without ``--vary`` is exit 2."""
    used = placeholders(text) + (placeholders(machine[1]) if machine else [])
    names = [name for name, _ in vary]
    for name in used:
        if name not in names:
            where = script if name in placeholders(text) else machine[0]  # type: ignore[index]
            raise usage_error(f"{where}: {{{name}}} has no --vary {name}=V1,V2,...")
    for name in names:
        if name not in used:
            raise usage_error(f"--vary {name}: {{{name}}} appears neither in {script}"
                              + (f" nor in {machine[0]}" if machine else ""))
    total = math.prod(len(values) for _, values in vary)
    if total > MAX_RUNS:
        raise usage_error(f"--vary: {total} combinations, more than {MAX_RUNS} runs")
    jobs: list[Job] = []
    varied_lines = [(number, line) for number, line in enumerate(text.splitlines(), start=1)
                    if placeholders(line)]
    for combination in itertools.product(*(values for _, values in vary)):
        values = dict(zip(names, combination))
        _check_cml(script, varied_lines, values)
        label = ",".join(f"{n}={v}" for n, v in values.items())
        run_machine = (machine[0], substitute(machine[1], values)) if machine else None
        jobs.append(make_job(f"{script}[{label}]", substitute(text, values), script.parent,
                             motors=motors, firmware=firmware, until=until,
                             machine=run_machine, figures=True,
                             values=tuple(values.items())))
    return jobs


def _check_cml(script: Path, lines: list[tuple[int, str]], values: dict[str, str]) -> None:
    """Each CML line with a placeholder is still CML with ``values`` put in: ``S.1={S}``
    with S=abc would be a line the motor refuses in silence, and the run would pass."""
    for number, template in lines:
        line = substitute(template, values)
        try:
            step = parse_line(line.rstrip("\r"), number)
        except ScriptError:
            continue                    # a directive: make_job says what is wrong with it
        if step.kind != "send":
            continue
        try:
            parse(line.rstrip("\r"))
        except CmlSyntaxError as exc:
            given = ", ".join(f"{name}={values[name]}" for name in placeholders(template))
            reason = str(exc).split(" at column ")[0]
            raise usage_error(f"--vary {given}: line {number} of {script} becomes {line!r}, "
                              f"not CML ({reason})") from None


def sweep(
    script: Path = typer.Argument(..., metavar="SCRIPT", help="Script with {NAME} "
                                  "placeholders."),
    vary: list[str] = typer.Option(..., "--vary", metavar="NAME=V1,V2,...",
                                   help="Values of {NAME}; repeat for a grid."),
    machine: Path | None = typer.Option(None, "--machine", metavar="AXIS.toml",
                                           help="Machine file ({NAME} replaced too)."),
    jobs: int | None = typer.Option(None, "--jobs", "-j", metavar="N", help=JOBS_HELP),
    scheduler: str | None = typer.Option(None, "--scheduler", metavar="tcp://HOST:8786",
                                            help=SCHEDULER_HELP),
    results: Path | None = typer.Option(
        None, "--results", metavar="FILE.csv",
        help="One row per run: CSV, or Parquet for FILE.parquet (needs pyarrow)."),
    plot: Path | None = typer.Option(None, "--plot", metavar="FILE.png",
                                        help="Draw --figure against the varied values."),
    figure: str = typer.Option("peak_speed", "--figure", metavar="NAME",
                               help="Figure for --plot: final_position, peak_speed, "
                                    "peak_torque, peak_temperature, duration_s "
                                    "(m2.peak_speed for motor 2)."),
    motors: int = typer.Option(1, "--motors", min=1, max=15, help=MOTORS_HELP),
    firmware_choice: FirmwareChoice = typer.Option(FirmwareChoice.cm2, "--firmware",
                                                   help=FIRMWARE_HELP),
    until: float | None = typer.Option(None, "--until", metavar="SECONDS",
                                          help=UNTIL_HELP),
    junit: Path | None = typer.Option(None, "--junit", metavar="FILE.xml",
                                         help="Write JUnit XML: one testcase per run."),
) -> None:
    """Run one script for every combination of --vary values; one results row per run."""
    firmware = firmware_choice.value
    check_options(motors, firmware, until)
    if script.is_dir():
        raise usage_error(f"{script}: sweep takes one script, not a directory")
    path = script_paths([script])[0]
    text = read_text(path)
    machine_text = (str(machine), read_text(machine, "machine file")) if machine else None
    varied = parse_vary(vary)
    column = figure_column(figure, motors) if plot is not None else None
    built = prepare(lambda: build_jobs(path, text, machine_text, varied, motors, firmware,
                                       until))
    check_outputs(junit=junit, results=results, plot=plot)
    if plot is not None and plot.suffix.lower() not in PLOT_SUFFIXES:
        raise usage_error(f"--plot {plot}: PNG, SVG or PDF by extension")
    if plot is not None:
        from ...needs import require_extra
        require_extra("plot", "sweep --plot")       # before the runs, not after them
    engine = start_engine(jobs, scheduler, len(built))
    run = run_all(engine, built, "sweep")
    write_outputs(run, junit, results, "coolmuscle.sweep")
    if plot is not None and column is not None and run.done:
        from .sweepplot import plot_sweep  # noqa: PLC0415  (matplotlib is slow to import)
        plot_sweep(plot, run.jobs, run.outcomes, column, title=str(path))
    print_summary(run, value_names=[n for n, _ in varied],
                  figures=("m1.final_position", "m1.peak_speed", "m1.peak_torque"))
    sys.stdout.flush()
    if run.exit_code():
        raise typer.Exit(run.exit_code())
