"""Plots of a trace: stacked position, speed and torque panels over a status and I/O timeline.

Drawn like the charts of cml-users-guide.txt 4.1 (speed against time, with the
in-position and output signals under it): one colour per motor in every panel, the
target dashed, speed in pulses/s with min⁻¹ on the right, and a timeline with one
status bar per motor (moving, in position, free, push, push complete, alarm, emergency
stop; the legend lists those that occur) and a
logic-analyser row for every input and output that is ever on.  Panels for the
analog input/output and the external encoder count appear only when those change.
Sample instants include every discrete change and solved pulse edge, so steps are
drawn where they happen.  Readable for 1 to 15 motors (the figure grows with the
number of timeline rows).  When two motors interpolated (4.4), or when asked for, a
panel beside the others draws the pair's XY path, as the figures of 4.4 do.
matplotlib runs headless (Agg).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...device.api import Device
from ...motor.state import output_functions as out
from ...motor.status import ALARM_BITS, Ux
from ...needs import needs_extra
from ...sim.kernel import NS_PER_S

with needs_extra("plot", "plotting (--plot)"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.typing import ColorType

    from .recorder import Sample, TraceRecorder

#: Status classes of the timeline bar, in priority order (6.6 ?99).
STATUS_COLORS = {
    "alarm": "#d62728", "emergency stop": "#7f0000", "motor free": "#f2c200",
    "push complete": "#3f007d", "push": "#9467bd", "in position": "#2ca02c",
    "moving": "#9ecae1",
}
ROW_HEIGHT_IN = 0.24
MAX_POINTS = 2000


class PlotFormatError(ValueError):
    """A plot path whose extension matplotlib cannot write."""


def check_plot_path(path: str | Path) -> None:
    """Refuse, before anything runs, a plot file matplotlib could not write."""
    suffix = Path(path).suffix.lower().lstrip(".")
    formats = plt.figure().canvas.get_supported_filetypes()
    plt.close("all")
    if suffix not in formats:
        known = ", ".join(f".{f}" for f in sorted(formats))
        raise PlotFormatError(f"cannot plot to {path}: the extension decides the format; "
                              f"one of {known}")


def status_class(ux: int) -> str:
    """The timeline colour class of a Ux value."""
    if ux & int(ALARM_BITS):
        return "alarm"
    if ux & Ux.EMERGENCY_STOP:
        return "emergency stop"
    if ux & Ux.MOTOR_FREE:
        return "motor free"
    if ux & Ux.PUSH:
        return "push complete" if ux & Ux.IN_POSITION else "push"   # Ux 40 (4.1.4)
    if ux & Ux.IN_POSITION:
        return "in position"
    return "moving"


def _finite(values: Sequence[float]) -> list[float]:
    return [v if math.isfinite(v) else float("nan") for v in values]


def _changes(values: Sequence[float]) -> bool:
    return any(v != values[0] for v in values)


#: Output functions (ch. 3 K34; CM1 Appendix A K34) as the timeline labels them.
OUTPUT_FUNCTIONS = {out.OUT_NONE: "no function", out.OUT_IN_POSITION: "in-position",
                    out.OUT_ALARM: "alarm", out.OUT_GENERAL: "general",
                    out.OUT_ORIGIN_DONE: "origin done", out.OUT_MERGE_PULSE: "merge pulse",
                    out.OUT_ROTATION_PULSE: "rotation pulse", out.OUT_MOTOR_FREE: "motor free",
                    out.OUT_PUSH: "push", out.OUT_FOLLOWS_O1: "O1/F1", out.OUT_FOLLOWS_O2: "O2/F2",
                    out.OUT_ANALOG: "analog", out.OUT_PUSH_AT_LEVEL: "push torque reached"}


def _bit_rows(samples: list[Sample], motor: int, count: int, multi: bool,
              functions: Sequence[int] = ()) -> list[tuple[str, list[bool]]]:
    """Inputs and outputs that are ever on (or change), as (label, bits); an output is
    labelled with its K34 function, ``functions[n - 1]`` (``OUT1 in-position``)."""
    rows = []
    prefix = f"ID{motor} " if multi else ""
    for kind, field in (("IN", "inputs"), ("OUT", "outputs")):
        for n in range(count if kind == "IN" else 4):
            bits = [bool(getattr(s, field) >> n & 1) for s in samples]
            if any(bits):
                label = f"{prefix}{kind}{n + 1}"
                if kind == "OUT" and n < len(functions):
                    label += f" {OUTPUT_FUNCTIONS.get(functions[n], 'no function')}"
                rows.append((label, bits))
    return rows


def _status_spans(t: list[float], samples: list[Sample], end: float
                  ) -> dict[str, list[tuple[float, float]]]:
    spans: dict[str, list[tuple[float, float]]] = {}
    start, current = t[0], status_class(samples[0].status)
    for x, s in zip(t[1:], samples[1:]):
        cls = status_class(s.status)
        if cls != current:
            spans.setdefault(current, []).append((start, x - start))
            start, current = x, cls
    spans.setdefault(current, []).append((start, max(end - start, 0.0)))
    return spans


#: Five dark colours that stay distinct from tab10 (for motors 11..15).
_EXTRA = ("#393b79", "#637939", "#8c6d31", "#843c39", "#7b4173")


def _palette(n: int) -> list[ColorType]:
    """tab10, then five darker colours: 15 motors, none faint."""
    cmap = plt.get_cmap("tab10")
    colours: list[ColorType] = [cmap(i) for i in range(10)]
    colours += _EXTRA
    return [colours[i % len(colours)] for i in range(n)]


def _speed_axis(ax: Axes, ppr: set[int]) -> None:
    """min⁻¹ on the right when every motor has the same resolution (K37)."""
    if len(ppr) != 1:
        return
    (p,) = ppr
    def to_rpm(v: Any) -> Any:          # pulses/s (numbers or numpy arrays) -> min⁻¹
        return v * 60.0 / p

    def to_pps(r: Any) -> Any:
        return r * p / 60.0
    right = ax.secondary_yaxis("right", functions=(to_rpm, to_pps))
    right.set_ylabel("min⁻¹")


def interpolated_pairs(recorder: TraceRecorder) -> list[tuple[int, int]]:
    """(X, Y) IDs of every pair of motors that followed an interpolation path (4.4)."""
    return recorder.feed.interpolated_pairs()


@dataclass
class PlotData:
    """What a trace plot shows, read from a recorder: the sample instants, each motor's
    samples and what the panels need to know of each motor.  Read in the model's thread
    (:func:`plot_times`, :func:`sample_motors`, :func:`plot_facts`); drawing it
    (:func:`draw_plot`) touches no model state, so it may run in any thread."""

    times: list[int]
    samples: dict[int, list[Sample]]
    input_counts: dict[int, int]
    output_functions: dict[int, list[int]]
    analog_out: dict[int, bool]            # K35 is not 0: the analog output is in use
    stoppers: dict[int, list[list[float]]]   # each motor's stoppers at each instant
    pulses_per_rev: set[int]
    pairs: list[tuple[int, int]]


def plot_times(recorder: TraceRecorder, step: float | None = None) -> list[int]:
    """The instants a plot of everything recorded up to now samples (the model's thread)."""
    end_ns = recorder.feed.now
    span = max((end_ns - recorder.start) / NS_PER_S, 1e-3)
    return recorder.times(step or span / MAX_POINTS, end_ns)


def sample_motors(recorder: TraceRecorder, times: Sequence[int]) -> dict[int, list[Sample]]:
    """Every motor's samples at ``times`` (the model's thread; past instants, exact)."""
    return {mid: [recorder.sample(mid, x) for x in times] for mid in recorder.motor_ids}


def plot_facts(recorder: TraceRecorder, times: list[int], samples: dict[int, list[Sample]],
               xy: Sequence[tuple[int, int]] | None = None) -> PlotData:
    """The plot's data: ``samples`` at ``times`` and what each motor's panels need (the
    model's thread).  ``xy``: pairs whose XY path is drawn (default: those that
    interpolated, 4.4; ``[]`` for none)."""
    traces = recorder.traces
    motors = recorder.motor_ids
    pairs = [p for p in (interpolated_pairs(recorder) if xy is None else xy)
             if p[0] in samples and p[1] in samples]
    return PlotData(times=times, samples=samples,
                    input_counts={m: traces[m].input_count for m in motors},
                    output_functions={m: list(traces[m].output_functions()) for m in motors},
                    analog_out={m: recorder.chain.get_param(m, 35) != 0 for m in motors},
                    stoppers={m: [traces[m].stoppers(x) for x in times] for m in motors},
                    pulses_per_rev={traces[m].pulses_per_rev for m in motors}, pairs=pairs)


def plot_trace(recorder: TraceRecorder, path: str | Path, *, step: float | None = None,
               title: str = "", xy: Sequence[tuple[int, int]] | None = None) -> Path:
    """Draw ``recorder`` into ``path`` (PNG, SVG or PDF by extension).

    ``xy``: pairs of motor IDs whose XY path is drawn beside the time panels (default:
    the pairs that interpolated; ``[]`` for none).
    """
    times = plot_times(recorder, step)
    return draw_plot(plot_facts(recorder, times, sample_motors(recorder, times), xy), path,
                     title)


def draw_plot(plot: PlotData, path: str | Path, title: str = "") -> Path:
    """Draw ``plot`` into ``path`` (PNG, SVG or PDF by extension).  Touches no model
    state and no pyplot state (a :class:`~matplotlib.figure.Figure` of its own), so it
    runs in any thread."""
    times, data = plot.times, plot.samples
    span = max((times[-1] - times[0]) / NS_PER_S, 1e-3)
    t = [x / NS_PER_S for x in times]
    motors = tuple(data)
    multi = len(motors) > 1
    colors = dict(zip(motors, _palette(len(motors))))
    bit_rows = {mid: _bit_rows(data[mid], mid, plot.input_counts[mid], multi,
                               plot.output_functions[mid])
                for mid in motors}
    occurring = {status_class(s.status) for d in data.values() for s in d}
    show_analog = any(_changes([s.analog_in for s in data[m]]) or plot.analog_out[m]
                      for m in motors)
    show_encoder = any(_changes([s.encoder for s in d]) for d in data.values())
    timeline_rows = len(motors) + sum(len(r) for r in bit_rows.values())

    panels = [("position", 2.6), ("speed", 2.0), ("torque", 1.6)]
    if show_analog:
        panels.append(("analog", 1.5))
    if show_encoder:
        panels.append(("encoder", 1.3))
    panels.append(("timeline", max(1.0, ROW_HEIGHT_IN * timeline_rows + 0.5)))
    heights = [h for _, h in panels]
    legend_outside = len(motors) > 4
    pairs = plot.pairs
    width = 12.5 if legend_outside else 11
    if pairs:
        fig = Figure(figsize=(width + 7, max(sum(heights) + 1.2, 8)))
        grid = fig.add_gridspec(len(panels), 2, height_ratios=heights,
                                width_ratios=[width, 6.5])
        axes = [fig.add_subplot(grid[0, 0])]
        axes += [fig.add_subplot(grid[i, 0], sharex=axes[0]) for i in range(1, len(panels))]
        _xy_panel(fig.add_subplot(grid[:, 1]), data, pairs, colors)
    else:
        fig = Figure(figsize=(width, sum(heights) + 1.2))
        axes = list(fig.subplots(len(panels), 1, sharex=True,
                                 gridspec_kw={"height_ratios": heights}))
    ax = {name: a for (name, _), a in zip(panels, axes)}
    for mid in motors:
        _draw_motor(ax, t, data[mid], mid, colors[mid])
        _draw_stoppers(ax["position"], mid, t, plot.stoppers[mid], colors[mid], multi)
    ax["position"].set_ylabel("position [pulse]")
    ax["speed"].set_ylabel("speed [pps]")
    ax["torque"].set_ylabel("torque [%]")
    _speed_axis(ax["speed"], plot.pulses_per_rev)
    if show_analog:
        ax["analog"].set_ylabel("analog [V]")
        ax["analog"].set_ylim(-0.1, 5.1)
    if show_encoder:
        ax["encoder"].set_ylabel("Ecnt")
    _draw_timeline(ax["timeline"], t, data, bit_rows, colors, span + t[0])
    for name, a in ax.items():
        if name != "timeline":
            a.grid(True, alpha=0.3)
    ax["timeline"].set_xlabel("virtual time [s]")
    ax["timeline"].set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1e-3)
    _legends(fig, ax, motors, colors, legend_outside, show_analog, occurring)
    fig.suptitle(title or "coolmuscle trace")
    fig.tight_layout(rect=(0, 0, 0.88 if legend_outside else 1, 1))
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path


def _draw_motor(ax: dict[str, Axes], t: list[float], samples: list[Sample], motor: int,
                color: object) -> None:
    label = f"ID{motor}"
    ax["position"].plot(t, [s.position for s in samples], color=color, linewidth=1.3,
                        label=label)
    ax["position"].plot(t, _finite([s.target for s in samples]), "--", color=color,
                        linewidth=0.8, alpha=0.7)
    ax["speed"].plot(t, [s.speed for s in samples], color=color, linewidth=1.1)
    ax["torque"].plot(t, [s.torque for s in samples], color=color, linewidth=1.0)
    if "analog" in ax:
        ax["analog"].plot(t, [s.analog_in * 5.0 / 1024 for s in samples], color=color,
                          linewidth=1.1)
        ax["analog"].plot(t, [s.analog_out for s in samples], ":", color=color, linewidth=1.0)
    if "encoder" in ax:
        ax["encoder"].step(t, [s.encoder for s in samples], where="post", color=color,
                           linewidth=1.0)


def _xy_panel(ax: Axes, data: dict[int, list[Sample]], pairs: Sequence[tuple[int, int]],
              colors: dict[int, ColorType]) -> None:
    """Each pair's path: the X motor's position across, the Y motor's up (4.4 figures);
    the command dashed, the start a circle, the end a square."""
    for x_id, y_id in pairs:
        xs, ys = data[x_id], data[y_id]
        color = colors[x_id]
        ax.plot([s.position for s in xs], [s.position for s in ys], color=color,
                linewidth=1.3, label=f"ID{x_id} x ID{y_id}")
        ax.plot([s.command for s in xs], [s.command for s in ys], "--", color="0.15",
                linewidth=0.9, dashes=(4, 3), zorder=3,
                label="command" if (x_id, y_id) == pairs[0] else None)
        ax.plot([xs[0].position], [ys[0].position], "o", color=color)
        ax.plot([xs[-1].position], [ys[-1].position], "s", color=color)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("X axis position [pulse]")
    ax.set_ylabel("Y axis position [pulse]")
    ax.set_title("XY path (\u25cb start, \u25a1 end, command dashed)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


def _draw_timeline(ax: Axes, t: list[float], data: dict[int, list[Sample]],
                   bit_rows: dict[int, list[tuple[str, list[bool]]]],
                   colors: dict[int, ColorType], end: float) -> None:
    """Per motor: a status bar, then one logic-analyser row per active input/output."""
    labels: list[tuple[float, str]] = []
    y = 0.0
    for mid in reversed(list(data)):
        for name, bits in reversed(bit_rows[mid]):
            ax.fill_between(t, y, [y + 0.7 * b for b in bits], step="post",
                            color=colors[mid], alpha=0.55, linewidth=0)
            ax.step(t, [y + 0.7 * b for b in bits], where="post", color=colors[mid],
                    linewidth=0.8)
            labels.append((y + 0.35, name))
            y += 1.0
        for cls, spans in _status_spans(t, data[mid], end).items():
            ax.broken_barh(spans, (y + 0.1, 0.6), facecolors=STATUS_COLORS[cls])
        labels.append((y + 0.4, f"ID{mid} status" if len(data) > 1 else "status"))
        y += 1.0
        if mid != next(iter(data)):
            ax.axhline(y - 0.05, color="0.75", linewidth=0.6)
    ax.set_yticks([v for v, _ in labels])
    ax.set_yticklabels([n for _, n in labels], fontsize="small" if len(labels) < 40 else 6)
    ax.set_ylim(-0.2, y)
    ax.grid(True, axis="x", alpha=0.3)


def _draw_stoppers(ax: Axes, motor: int, t: list[float], walls: list[list[float]],
                   color: object, multi: bool) -> None:
    """The machine file's stoppers (a pushed object, 4.1.4) as dotted lines, in the
    motor's user coordinates of each instant: a line steps where an origin set moved
    them, so the trace never crosses a stopper it did not touch."""
    if not walls or not walls[0]:
        return
    name = f"ID{motor} stopper" if multi else "stopper"
    for k in range(len(walls[0])):
        values = [w[k] for w in walls]
        ax.step(t, values, where="post", color=color, linestyle=":", linewidth=1.2)
        shown = f"{values[0]:g}" if values[-1] == values[0] else \
            f"{values[0]:g} -> {values[-1]:g}"
        ax.annotate(f"{name} {shown} (machine file)", (0.01, values[0]),
                    xycoords=("axes fraction", "data"), fontsize="x-small",
                    va="bottom", color=color)


def _legends(fig: Figure, ax: dict[str, Axes], motors: Sequence[int],
             colors: dict[int, ColorType], outside: bool, analog: bool,
             occurring: set[str] | None = None) -> None:
    status = [Patch(color=c, label=name) for name, c in STATUS_COLORS.items()
              if occurring is None or name in occurring]
    ax["timeline"].legend(handles=status, loc="upper left", bbox_to_anchor=(1.0, 1.0),
                          fontsize="x-small", frameon=False)
    if analog:
        ax["analog"].plot([], [], color="gray", label="input (?74)")
        ax["analog"].plot([], [], ":", color="gray", label="output (K35)")
        ax["analog"].legend(loc="upper right", fontsize="x-small")
    ax["position"].plot([], [], "--", color="gray", linewidth=0.8, label="target")
    if outside:
        handles = [Line2D([], [], color=colors[m], label=f"ID{m}") for m in motors]
        handles.append(Line2D([], [], color="gray", linestyle="--", label="target"))
        fig.legend(handles=handles, loc="upper right", bbox_to_anchor=(0.995, 0.96),
                   fontsize="small", title="motor")
    else:
        ax["position"].legend(loc="upper right", fontsize="small")


def plot(chain: Device, path: str | Path, title: str = "",
         xy: Sequence[tuple[int, int]] | None = None) -> Path:
    """Plot what ``chain``'s trace recorder holds (position, speed, torque, status and
    I/O), and the XY path of ``xy`` pairs (default: the pairs that interpolated, 4.4)."""
    from .recorder import record
    return plot_trace(record(chain), path, title=title, xy=xy)
