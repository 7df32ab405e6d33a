"""``coolmuscle compare`` and ``coolmuscle fit`` (docs/twin.md), registered on the main app.

Exit status: compare 0 when every line is within tolerance, 1 on any difference beyond
it; fit 0 when the machine file is written.  Both: 2 for bad input (a file that is not
a capture, a bad machine file, an unknown parameter, an output path that cannot be
written, a fit that does not converge or a parameter the session does not determine),
with one line and nothing written.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import typer

from ..cli.usage import UsageError
from .output import check_output

__all__ = ["register", "compare", "fit"]

REPORT_SUFFIXES = (".md", ".html", ".htm")
#: Difference lines printed before "... N more (see --report)".
SHOWN = 20


def _plot_check(plot: Path | None) -> None:
    if plot is not None:
        from .plot import PLOT_SUFFIXES
        check_output(plot, "--plot", PLOT_SUFFIXES)


def _positive(value: float, option: str, lo: float = 0.0) -> None:
    if not (math.isfinite(value) and value >= lo):
        raise UsageError(f"{option} must be a number of at least {lo:g}, not {value!r}")


def compare(
    session: Path = typer.Argument(..., metavar="SESSION.cml",
                                   help="A capture (coolmuscle capture)."),
    machine: Path | None = typer.Option(
        None, "--machine", metavar="M.toml",
        help="Machine file of the virtual motor (default: the capture's '# chain: "
             "machine=', else the default load)."),
    report: Path | None = typer.Option(None, "--report", metavar="OUT.md|OUT.html",
                                          help="Write the report (Markdown or HTML)."),
    plot: Path | None = typer.Option(None, "--plot", metavar="OUT.png",
                                        help="Plot real and virtual polled values "
                                             "(PNG, SVG or PDF)."),
    time_tolerance: float = typer.Option(0.02, "--time-tolerance", metavar="SECONDS",
                                         help="Timing tolerance of a line (default 0.02)."),
    time_relative: float = typer.Option(
        0.02, "--time-relative", metavar="FRACTION",
        help="... or this fraction of the time since the line sent before it, if more."),
    noise: float = typer.Option(1.0, "--noise", metavar="UNITS",
                                help="Noise of a polled value beyond its rounding "
                                     "(default 1 unit)."),
    junit: Path | None = typer.Option(
        None, "--junit", metavar="FILE.xml",
        help="Also write JUnit XML: a case per line received, with its capture line."),
) -> None:
    """Replay a captured session on the virtual motor and report every difference."""
    from .compare import Tolerance, compare_session
    for value, option in ((time_tolerance, "--time-tolerance"),
                          (time_relative, "--time-relative"), (noise, "--noise")):
        _positive(value, option)
    if report is not None:
        check_output(report, "--report", REPORT_SUFFIXES)
    if junit is not None:
        check_output(junit, "--junit", (".xml",))
    _plot_check(plot)
    tolerance = Tolerance(time_abs=time_tolerance, time_rel=time_relative, noise=noise)
    result = compare_session(session, machine, tolerance)
    write = sys.stdout.write
    write(f"coolmuscle compare: {result.heading()}\n")
    captured = result.session
    write(f"tolerance: {tolerance.describe(captured.baud, captured.bits_per_byte)}\n")
    write(f"{result.summary()}\n")
    diffs = result.differences
    for verdict in diffs[:SHOWN]:
        write(f"  {verdict.describe()}\n")
    if len(diffs) > SHOWN:
        write(f"  ... {len(diffs) - SHOWN} more" + (" (all in the report)\n" if report
                                                     else " (--report lists them all)\n"))
    from .output import write_atomic
    if plot is not None:
        from .plot import write_figure
        write_figure(result.panels, plot, result.heading())
        write(f"wrote {plot}\n")
    if report is not None:
        if report.suffix.lower() == ".md":
            shown = None
            if plot is not None:
                shown = str(plot.resolve().relative_to(report.resolve().parent)) \
                    if plot.resolve().is_relative_to(report.resolve().parent) else str(plot)
            text = result.to_markdown(shown)
        else:
            text = result.to_html()
        write_atomic(report, text.encode("utf-8"))
        write(f"wrote {report}\n")
    if junit is not None:
        from ..ci.junit import write_junit
        from .compare import junit_suite
        write_junit(junit, [junit_suite(result, session)])
        write(f"wrote {junit}\n")
    write(f"coolmuscle: {result.verdict_line()}\n")
    if not result.ok:
        raise typer.Exit(1)


def fit(
    session: Path = typer.Argument(..., metavar="SESSION.cml",
                                   help="A capture (coolmuscle capture)."),
    machine_out: Path = typer.Option(..., "--machine-out", metavar="M.toml",
                                     help="Write the fitted machine file here."),
    machine: Path | None = typer.Option(
        None, "--machine", metavar="BASE.toml",
        help="Start from this machine file (its other keys are kept; default: the "
             "capture's '# chain: machine=', else the default load)."),
    params: str | None = typer.Option(
        None, "--params", metavar="NAME,...",
        help="Parameters to fit: inertia, friction, torque, kp (gain), rotor_inertia, "
             "rated_torque, peak_torque, max_speed, cw, ccw; NAME.ID for one motor "
             "(default: inertia,friction,kp)."),
    plot: Path | None = typer.Option(None, "--plot", metavar="OUT.png",
                                        help="Plot measured, start and fitted values."),
    max_replays: int = typer.Option(300, "--max-replays", metavar="N", min=2,
                                    help="Give up after this many replays (default 300)."),
) -> None:
    """Fit the machine file's load and servo model to a captured session."""
    from .fit import fit_session
    check_output(machine_out, "--machine-out", (".toml",))
    _plot_check(plot)
    write = sys.stdout.write

    def progress(replays: int, rms: float) -> None:
        if replays == 1 or replays % 10 == 0:
            write(f"  replay {replays}: weighted residual RMS {rms:.3f}\n")
            sys.stdout.flush()

    from .session import POLLED, read_session
    captured = read_session(session)
    counts = {q: sum(1 for p in captured.polls if p.quantity == q) for q in POLLED}
    shown = ", ".join(f"{q} {n}" for q, n in counts.items() if n)
    write(f"coolmuscle fit: {session.name} ({captured.duration:.1f} s, {len(captured.polls)} "
          f"polled values{': ' + shown if shown else ''})\n")
    result = fit_session(captured, machine, params, max_replays=max_replays,
                         on_replay=progress)
    write(f"converged after {result.replays} replays in {result.seconds:.1f} s: weighted "
          f"residual RMS {result.rms:.3f} (start {result.rms_start:.3f}; 1 is the noise "
          "the data allows)\n")
    write("\n".join(result.lines()) + "\n")
    rms = ", ".join(f"{q} {v:.3g}" for q, v in result.quantity_rms.items())
    write(f"RMS of real - fitted: {rms}\n")
    text = result.machine_text()          # checked before anything is written
    if plot is not None:
        from .plot import write_figure
        write_figure(result.panels, plot, f"{session.name}: measured and fitted")
        write(f"wrote {plot}\n")
    from .output import write_atomic
    write_atomic(machine_out, text.encode("utf-8"))
    write(f"wrote {machine_out}\n")


def register(app: typer.Typer) -> None:
    """Add ``compare`` and ``fit`` to the ``coolmuscle`` command."""
    app.command()(compare)
    app.command()(fit)
