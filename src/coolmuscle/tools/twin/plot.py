"""Plots of the twin: one panel per polled quantity, the real motor beside the virtual one.

Used by ``compare`` (real and virtual replies, differences marked) and ``fit`` (measured,
the start and the fitted model).  Same conventions as the trace plots (docs/plots.md):
matplotlib headless (Agg), time in seconds on a shared axis, PNG, SVG or PDF by the
extension.  The figure is 10 x (1 + 2 x panels) inches at 100 dpi, so a PNG is 1000
pixels wide and 100 + 200 x panels high.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ...needs import needs_extra
from .output import write_atomic
from .session import POLLED

with needs_extra("twin", "the twin's plots (compare, fit)"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure

__all__ = ["PLOT_SUFFIXES", "Panel", "Series", "figure_png", "write_figure"]

PLOT_SUFFIXES = (".png", ".svg", ".pdf")

DPI = 100
WIDTH_IN = 10.0
PANEL_IN = 2.0

_NAMES = {"Px": "position Px (?96)", "Pe": "position error Pe (?95)", "Sx": "speed Sx (?97)",
          "Ix": "torque Ix (?98)"}


@dataclass
class Series:
    """One curve: ``style`` is ``"real"`` (dots), ``"virtual"`` (line), ``"start"``
    (dashed), ``"fitted"`` (line) or ``"differs"`` (red crosses)."""

    label: str
    times: list[float]
    values: list[float]
    style: str


@dataclass
class Panel:
    motor: int
    quantity: str
    series: list[Series] = field(default_factory=list)

    @property
    def title(self) -> str:
        unit = POLLED[self.quantity][1]
        return f"ID{self.motor} {_NAMES[self.quantity]}, {unit}"


_STYLES: dict[str, dict[str, object]] = {
    "real": {"linestyle": "none", "marker": ".", "markersize": 3, "color": "#1f77b4",
             "zorder": 3},
    "virtual": {"linewidth": 1.2, "color": "#ff7f0e", "zorder": 2},
    "fitted": {"linewidth": 1.2, "color": "#2ca02c", "zorder": 2},
    "start": {"linewidth": 1.0, "color": "#7f7f7f", "linestyle": "--", "zorder": 1},
    "differs": {"linestyle": "none", "marker": "x", "markersize": 6, "color": "#d62728",
                "zorder": 4},
}


def _draw(panels: Sequence[Panel], title: str) -> Figure:
    count = max(1, len(panels))
    fig, axes = plt.subplots(count, 1, figsize=(WIDTH_IN, 1.0 + PANEL_IN * count),
                             dpi=DPI, sharex=True, squeeze=False)
    for ax, panel in zip(axes[:, 0], panels, strict=False):
        for series in panel.series:
            if len(series.times):
                ax.plot(series.times, series.values, label=series.label,
                        **_STYLES[series.style])
        ax.set_title(panel.title, fontsize=9, loc="left")
        ax.grid(True, alpha=0.3)
    if panels:                       # the same series in every panel: one legend, on top
        handles, labels = axes[0, 0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="upper right", ncol=len(labels), fontsize=8,
                   frameon=False)
    if not panels:
        axes[0, 0].text(0.5, 0.5, "no polled values in this session", ha="center",
                        va="center", transform=axes[0, 0].transAxes)
    axes[-1, 0].set_xlabel("time since the capture began, s")
    fig.suptitle(title, fontsize=10, x=0.08, ha="left")
    fig.subplots_adjust(left=0.08, right=0.98, top=1 - 0.6 / (1.0 + PANEL_IN * count),
                        bottom=0.5 / (1.0 + PANEL_IN * count), hspace=0.35)
    return fig


def write_figure(panels: Sequence[Panel], path: str | os.PathLike[str], title: str) -> Path:
    """Draw ``panels`` into ``path`` (the extension decides the format), whole or not at
    all."""
    path = Path(path)
    return write_atomic(path, _render(panels, title, path.suffix.lower().lstrip(".")))


def figure_png(panels: Sequence[Panel], title: str) -> bytes:
    """The same figure as PNG bytes (embedded in the HTML report)."""
    return _render(panels, title, "png")


def _render(panels: Sequence[Panel], title: str, fmt: str) -> bytes:
    fig = _draw(panels, title)
    try:
        out = io.BytesIO()
        fig.savefig(out, format=fmt)
        return out.getvalue()
    finally:
        plt.close(fig)
