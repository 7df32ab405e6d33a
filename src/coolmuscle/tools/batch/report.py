"""What a batch or sweep writes: the results table (CSV or Parquet) and JUnit XML.

Results: one row per run, in job order: the ``--vary`` values (sweep), ``script``,
``status`` (pass, fail, error, ran = no expectations, not run = left by a Ctrl-C),
``expectations``, ``matched``, ``duration_s`` (virtual, to the ns), ``first_difference``
and the figures (:mod:`coolmuscle.tools.batch.figures`).  CSV numbers are written as
``coolmuscle run --trace`` writes them (whole numbers bare, others to 6 decimals), so a
figure reads the same in both files; the file never holds wall times, so the same runs
give the same bytes on any engine.  A ``.parquet`` path writes Parquet (typed columns)
when pyarrow is installed.

JUnit XML (the schema CI systems read): one ``<testsuite>``, one ``<testcase>`` per
script; a failed expectation or ``@until`` timeout is a ``<failure>``, a model error an
``<error>``, a run a Ctrl-C left unfinished ``<skipped>``; the message is the first
difference.
"""

from __future__ import annotations

import csv
import logging
import math
from collections.abc import Sequence
from pathlib import Path

from ...errors import CoolMuscleError
from ..trace.recorder import parquet_available
from .figures import ns_to_seconds
from .job import Job, Outcome

log = logging.getLogger(__name__)

BASE_COLUMNS = ("script", "status", "expectations", "matched", "duration_s",
                "first_difference")


class ReportError(CoolMuscleError, ValueError):
    """An output path that cannot be written (checked before anything runs)."""


def check_output(path: Path, what: str, parquet_ok: bool = False) -> None:
    """Refuse, before a run, a ``--junit``/``--results``/``--plot`` path we cannot write."""
    parent = path.expanduser().parent
    if not parent.is_dir():
        raise ReportError(f"{what} {path}: directory {parent} does not exist")
    if path.is_dir():
        raise ReportError(f"{what} {path} is a directory")
    if path.suffix.lower() == ".parquet":
        if not parquet_ok:
            raise ReportError(f"{what} {path}: Parquet is for --results only")
        if not parquet_available():
            raise ReportError(f"cannot write {path}: Parquet results need pyarrow (pip "
                              "install pyarrow); a .csv path needs nothing")


def format_value(value: object) -> str:
    """As the trace CSV writes numbers: ``10000``, ``2.133573``, ``inf``; text as is."""
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
        if value.is_integer() and abs(value) < 1e15:
            return str(int(value))
        return f"{value:.6f}"
    return str(value)


def table(jobs: Sequence[Job], outcomes: Sequence[Outcome | None]
          ) -> tuple[list[str], list[list[object]]]:
    """The header and rows of the results (job order; unfinished runs as ``not run``)."""
    names = [name for name, _ in jobs[0].values] if jobs else []
    figure_keys: list[str] = []
    for outcome in outcomes:
        for key, _ in outcome.figures if outcome is not None else ():
            if key not in figure_keys:
                figure_keys.append(key)
    header = names + list(BASE_COLUMNS) + figure_keys
    rows: list[list[object]] = []
    for job, outcome in zip(jobs, outcomes):
        values = dict(job.values)
        row: list[object] = [values.get(n, "") for n in names]
        if outcome is None:
            row += [job.name, "not run", 0, 0, "", ""] + [""] * len(figure_keys)
        else:
            figures = dict(outcome.figures)
            row += [job.name, outcome.status, outcome.expectations, outcome.matched,
                    ns_to_seconds(outcome.end_ns), outcome.message]
            row += [figures.get(k, "") for k in figure_keys]
        rows.append(row)
    return header, rows


def write_results(path: Path, jobs: Sequence[Job], outcomes: Sequence[Outcome | None]
                  ) -> Path:
    """CSV, or Parquet for a ``.parquet`` path."""
    header, rows = table(jobs, outcomes)
    path = path.expanduser()
    if path.suffix.lower() == ".parquet":
        return _write_parquet(path, header, rows)
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        for row in rows:
            writer.writerow([format_value(v) for v in row])
    return path


def _write_parquet(path: Path, header: list[str], rows: list[list[object]]) -> Path:
    import pyarrow as pa  # noqa: PLC0415  (optional, checked by check_output)
    import pyarrow.parquet as pq  # noqa: PLC0415

    columns = {}
    for index, name in enumerate(header):
        values = [row[index] for row in rows]
        present = [v for v in values if v != ""]
        if name == "duration_s":  # seconds to the ns as text in CSV; a number here
            columns[name] = pa.array([float(str(v)) if v != "" else None for v in values],
                                     pa.float64())
        elif present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
            columns[name] = pa.array([None if v == "" else v for v in values], pa.int64())
        elif present and all(isinstance(v, (int, float)) for v in present):
            columns[name] = pa.array([v if isinstance(v, (int, float)) else None
                                      for v in values], pa.float64())
        else:
            columns[name] = pa.array([str(v) for v in values], pa.string())
    pq.write_table(pa.table(columns), str(path))
    return path


def write_junit(path: Path, jobs: Sequence[Job], outcomes: Sequence[Outcome | None],
                suite: str = "coolmuscle.batch") -> Path:
    """JUnit XML: one testcase per script, failure text = the first difference."""
    from ..ci.junit import Case, Suite
    from ..ci.junit import write_junit as write

    cases = []
    for job, outcome in zip(jobs, outcomes):
        if outcome is None:
            cases.append(Case(job.name, suite, None, "skipped",
                              "not run: the batch was interrupted"))
        elif outcome.status in ("fail", "error"):
            cases.append(Case(job.name, suite, outcome.wall_s,
                              "failure" if outcome.status == "fail" else "error",
                              outcome.message, outcome.kind or outcome.status))
        else:
            cases.append(Case(job.name, suite, outcome.wall_s))
    done = [o for o in outcomes if o is not None]
    return write(path, [Suite(suite, cases, sum(o.wall_s for o in done))])
