"""Plots of a trace: stacked position, speed and torque panels plus a status and I/O timeline.

Drawn like the charts of cml-users-guide.txt 4.1 (speed against time, with the
in-position and output signals under it); when two motors interpolated (4.4), or when
asked for, a panel beside them draws the pair's XY path, as the figures of 4.4 do.
matplotlib runs headless (Agg).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .sim.kernel import NS_PER_S  # noqa: E402

if TYPE_CHECKING:
    from .sim.trace import TraceRecorder


def _finite(values: list[float]) -> list[float]:
    return [v if math.isfinite(v) else float("nan") for v in values]


def interpolated_pairs(recorder: "TraceRecorder") -> list[tuple[int, int]]:
    """(X, Y) IDs of every pair of motors that followed an interpolation path (4.4)."""
    pairs: list[tuple[int, int]] = []
    for motor in recorder.chain.motors.values():
        path = getattr(motor, "path", None)
        if path is not None and (path.x.id, path.y.id) not in pairs:
            pairs.append((path.x.id, path.y.id))
    return sorted(pairs)


def plot_trace(recorder: "TraceRecorder", path: str | Path, *, step: float | None = None,
               title: str = "", xy: Sequence[tuple[int, int]] | None = None) -> Path:
    """Draw ``recorder`` into ``path`` (PNG, SVG or PDF by extension).

    ``xy``: pairs of motor IDs whose XY path to draw beside the time panels (default:
    the pairs that interpolated; ``[]`` for none).
    """
    end = recorder.chain.kernel.now
    span = max((end - recorder.start) / NS_PER_S, 1e-3)
    times = recorder.times(step or span / 2000.0, end)
    t = [x / NS_PER_S for x in times]
    motors = recorder.motor_ids
    pairs = [p for p in (interpolated_pairs(recorder) if xy is None else xy)
             if p[0] in motors and p[1] in motors]
    ratios = [3, 2, 2, 1.4]
    if pairs:
        fig = plt.figure(figsize=(16, 9))
        grid = fig.add_gridspec(4, 2, height_ratios=ratios, width_ratios=[10, 6])
        axes = [fig.add_subplot(grid[0, 0])]
        axes += [fig.add_subplot(grid[i, 0], sharex=axes[0]) for i in (1, 2, 3)]
        _xy_panel(fig.add_subplot(grid[:, 1]), recorder, times, pairs)
    else:
        fig, axes = plt.subplots(4, 1, sharex=True, figsize=(10, 9),
                                 gridspec_kw={"height_ratios": ratios})
    ax_pos, ax_speed, ax_torque, ax_io = axes
    for mid in motors:
        samples = [recorder.sample(mid, x) for x in times]
        label = f"ID{mid}"
        ax_pos.plot(t, _finite([s.position for s in samples]), label=f"{label} position")
        ax_pos.plot(t, _finite([s.target for s in samples]), "--", linewidth=0.8,
                    label=f"{label} target")
        ax_speed.plot(t, [s.speed for s in samples], label=label)
        ax_torque.plot(t, [s.torque for s in samples], label=label)
        _timeline(ax_io, t, samples, mid, len(motors))
    ax_pos.set_ylabel("position [pulse]")
    ax_speed.set_ylabel("speed [pps]")
    ax_torque.set_ylabel("torque [%]")
    ax_io.set_xlabel("virtual time [s]")
    for ax in axes[:3]:
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _xy_panel(ax: "plt.Axes", recorder: "TraceRecorder", times: list[int],
              pairs: Sequence[tuple[int, int]]) -> None:
    """The path of each pair: X motor's position across, Y motor's up (4.4 figures)."""
    for x_id, y_id in pairs:
        xs = [recorder.sample(x_id, t) for t in times]
        ys = [recorder.sample(y_id, t) for t in times]
        line, = ax.plot([s.position for s in xs], [s.position for s in ys],
                        label=f"ID{x_id} x ID{y_id} position")
        ax.plot([s.command for s in xs], [s.command for s in ys], "--", linewidth=0.8,
                color=line.get_color(), label=f"ID{x_id} x ID{y_id} command")
        ax.plot([xs[0].position], [ys[0].position], "o", color=line.get_color())
        ax.plot([xs[-1].position], [ys[-1].position], "s", color=line.get_color())
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("X axis position [pulse]")
    ax.set_ylabel("Y axis position [pulse]")
    ax.set_title("XY path (o start, □ end)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


def _timeline(ax: "plt.Axes", t: list[float], samples: list, motor: int, count: int) -> None:
    """In-position, motor free, alarm, and each input/output as stacked steps."""
    rows = [("in-pos", [bool(s.status & 8) for s in samples]),
            ("free", [bool(s.status & 16) for s in samples]),
            ("alarm", [bool(s.status & 0b1_1100_0111) for s in samples])]
    for n in range(6):
        bits = [bool(s.inputs >> n & 1) for s in samples]
        if any(bits):
            rows.append((f"IN{n + 1}", bits))
    for n in range(4):
        bits = [bool(s.outputs >> n & 1) for s in samples]
        if any(bits):
            rows.append((f"OUT{n + 1}", bits))
    base = (motor - 1) * (len(rows) + 1)
    labels = []
    for i, (name, bits) in enumerate(rows):
        y = base + i
        ax.step(t, [y + 0.7 * b for b in bits], where="post", linewidth=1)
        labels.append((y + 0.35, f"{name}" if count == 1 else f"ID{motor} {name}"))
    ticks = list(ax.get_yticks()) if motor > 1 else []
    names = [lbl.get_text() for lbl in ax.get_yticklabels()] if motor > 1 else []
    ax.set_yticks(ticks + [y for y, _ in labels])
    ax.set_yticklabels(names + [n for _, n in labels], fontsize="small")
