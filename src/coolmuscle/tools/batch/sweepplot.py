"""``coolmuscle sweep --plot``: one figure of the runs against the varied values.

The x axis is the first ``--vary`` (numbers when every value is one, else the values as
labels); each combination of the other ``--vary`` values is a line of its own.  Runs
that failed are marked with a red cross; runs a Ctrl-C left unfinished are left out.
PNG, SVG or PDF by the file's extension (matplotlib, as ``coolmuscle run --plot``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

from .figures import ns_to_seconds
from .job import Job, Outcome

log = logging.getLogger(__name__)


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def figure_value(outcome: Outcome, column: str) -> float | None:
    """The figure ``column`` of a run as a number (``duration_s`` too)."""
    if column == "duration_s":
        return float(ns_to_seconds(outcome.end_ns))
    value = dict(outcome.figures).get(column)
    return float(value) if isinstance(value, (int, float)) else None


def plot_sweep(path: Path, jobs: Sequence[Job], outcomes: Sequence[Outcome | None],
               column: str, title: str = "") -> Path:
    """Draw ``column`` against the first varied value, one line per other combination."""
    from ...needs import needs_extra
    with needs_extra("plot", "sweep --plot"):
        import matplotlib  # noqa: PLC0415
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # noqa: PLC0415

    names = [n for n, _ in jobs[0].values]
    first = names[0]
    x_values: list[str] = []
    for job in jobs:
        value = dict(job.values)[first]
        if value not in x_values:
            x_values.append(value)
    numbers = [_number(v) for v in x_values]
    numeric = all(n is not None for n in numbers)
    position = {v: (n if numeric and n is not None else float(i))
                for i, (v, n) in enumerate(zip(x_values, numbers))}
    lines: dict[str, list[tuple[float, float, bool]]] = {}
    for job, outcome in zip(jobs, outcomes):
        if outcome is None:
            continue
        y = figure_value(outcome, column)
        if y is None:
            continue
        values = dict(job.values)
        label = ", ".join(f"{n}={values[n]}" for n in names[1:]) or column
        lines.setdefault(label, []).append((position[values[first]], y, outcome.ok))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, points in lines.items():
        points.sort()
        ax.plot([p[0] for p in points], [p[1] for p in points], marker="o", label=label)
        bad = [p for p in points if not p[2]]
        if bad:
            ax.plot([p[0] for p in bad], [p[1] for p in bad], "x", color="red",
                    markersize=10, mew=2)
    if not numeric:
        ax.set_xticks([position[v] for v in x_values], x_values)
    ax.set_xlabel(first)
    ax.set_ylabel(column)
    ax.set_title(title or f"{column} against {first}")
    ax.grid(True, alpha=0.3)
    if len(lines) > 1 or names[1:]:
        ax.legend(fontsize="small")
    fig.tight_layout()
    path = Path(path).expanduser()
    fig.savefig(path)
    plt.close(fig)
    return path
