"""Traces and plots: ``--trace`` CSV / Parquet, ``--plot`` panels.

The trace samples the closed-form history exactly; position-derived outputs
(rotation pulses) are evaluated at each sample and their edges are sample instants.
A plot is titled and labelled (status names, output rows by their K34 function, the
stopper, the XY command path); a plot file it cannot write fails before the run.
"""

from __future__ import annotations

import csv
import sys
import types
from pathlib import Path
from typing import Any

import matplotlib.figure
import matplotlib.image
import pytest

from coolmuscle.motor.signals.encoder import Gearing
from coolmuscle.sim.kernel import NS_PER_S, seconds
from coolmuscle.tools.cli import app as cli
from coolmuscle.tools.trace import recorder as trace_module
from coolmuscle.tools.trace.plot import plot as plot_chain
from coolmuscle.tools.trace.plot import status_class
from coolmuscle.tools.trace.recorder import FIELDS, TraceFormatError, record
from coolmuscle.tools.trace.recorder import trace as start_trace
from fixtures import ROOT, ChainFactory, run_coolmuscle

EXAMPLES = ROOT / "examples"

SCRIPT = """\
K34.1=77
K24.1=2000
S.1=100
A.1=100
P.1=6000
^.1
@until ^Ux\\.1=8$
@analog 700
@wait 0.5
"""


def _read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def test_trace_csv_has_every_column_and_the_pulse_edges_as_rows(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain()
    handle = start_trace(chain, tmp_path / "run.csv", step=0.01)
    chain.set_param(1, 34, 77)
    chain.set_param(1, 24, 2000)
    chain.motors[1].encoder.set_gearing(Gearing(ppr=1000))
    chain.set_param(1, 71, 5)
    chain.set_param(1, 38, 0)                    # the input below must not move the motor
    chain.execute("S.1=100, A.1=100, P.1=6000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(1))
    chain.set_analog(1, 700)
    chain.kernel.run(until=seconds(1.2))
    path = handle.close()
    header, rows = _read_csv(path)
    assert header == ["time_s"] + [f"m1.{f}" for f in FIELDS]
    col = {name: i for i, name in enumerate(header)}
    times = [round(float(r[0]) * NS_PER_S) for r in rows]
    edges = chain.motors[1].pulses.edge_times(0, chain.kernel.now)
    assert len(edges) == 11 and set(edges) <= set(times)
    for edge in edges:
        i = times.index(edge)
        assert rows[i][col["m1.outputs"]] != rows[i - 1][col["m1.outputs"]]
    last = rows[-1]
    assert last[col["m1.analog_in"]] == "700" and last[col["m1.encoder"]] == "6000"
    # K35=0: the target, ±1024 pulses per ±1.67 V, repeating: 6000 is -0.140625 of a range
    assert float(last[col["m1.analog_out"]]) == pytest.approx(2.5 - 1.67 * 0.140625, abs=1e-6)
    assert float(last[col["m1.position"]]) == pytest.approx(6000, abs=0.01)


def test_trace_analog_out_follows_k35(tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain()
    rec = record(chain)
    chain.set_param(1, 35, 2)                    # current position, ±1024 pulses
    chain.execute("S.1=10, A.1=100, P.1=512")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(2))
    assert rec.sample(1, 0).analog_out == 2.5
    assert rec.sample(1, seconds(2)).analog_out == pytest.approx(2.5 + 1.67 / 2, abs=1e-4)


def test_parquet_without_pyarrow_is_a_clear_error_before_anything_runs(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: Any,
        make_chain: ChainFactory) -> None:
    monkeypatch.setattr(trace_module, "parquet_available", lambda: False)
    with pytest.raises(TraceFormatError, match="pyarrow"):
        start_trace(make_chain(), tmp_path / "run.parquet")
    script = tmp_path / "s.cml"
    script.write_text("?96.1\n")
    with pytest.raises(SystemExit) as info:
        cli.main(["run", str(script), "--trace", str(tmp_path / "run.parquet")])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "Parquet traces need pyarrow" in err and "\n" == err[-1] and err.count("\n") == 1
    assert not (tmp_path / "run.parquet").exists()


def test_parquet_columns_and_types_with_pyarrow(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, make_chain: ChainFactory) -> None:
    """The Parquet writer against a stand-in for pyarrow (it is an optional
    dependency): one int64 or float64 array per column, written to the path."""
    written: dict[str, Any] = {}

    class Array(list):
        def __init__(self, values: list[Any], type: str) -> None:  # noqa: A002
            super().__init__(values)
            self.type = type

    pa = types.ModuleType("pyarrow")
    pa.int64 = lambda: "int64"                     # type: ignore[attr-defined]
    pa.float64 = lambda: "float64"                 # type: ignore[attr-defined]
    pa.array = Array                               # type: ignore[attr-defined]
    pa.table = lambda arrays: dict(arrays)         # type: ignore[attr-defined]
    pq = types.ModuleType("pyarrow.parquet")
    pq.write_table = lambda table, where: written.update(table=table, where=where)  # type: ignore[attr-defined]
    pa.parquet = pq                                # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "pyarrow", pa)
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", pq)
    monkeypatch.setattr(trace_module, "parquet_available", lambda: True)
    chain = make_chain()
    handle = start_trace(chain, tmp_path / "run.parquet", step=0.1)
    chain.execute("S.1=100, A.1=100, P.1=1000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(1))
    handle.close()
    table = written["table"]
    assert written["where"] == str(tmp_path / "run.parquet")
    assert list(table) == ["time_s"] + [f"m1.{f}" for f in FIELDS]
    assert table["m1.status"].type == "int64" and table["m1.position"].type == "float64"
    assert table["m1.status"][-1] == 8 and table["m1.position"][-1] == pytest.approx(1000)


def test_cli_run_writes_trace_and_plot(tmp_path: Path, capsys: Any) -> None:
    script = tmp_path / "pulses.cml"
    script.write_text(SCRIPT)
    out_csv, out_png = tmp_path / "run.csv", tmp_path / "run.png"
    with pytest.raises(SystemExit) as info:
        cli.main(["run", str(script), "--trace", str(out_csv), "--plot", str(out_png)])
    assert info.value.code in (0, None)
    header, rows = _read_csv(out_csv)
    assert "m1.analog_in" in header and len(rows) > 100
    image = matplotlib.image.imread(out_png)
    assert image.shape[0] > 800 and image.shape[1] > 1000
    capsys.readouterr()


def test_plot_grows_with_the_number_of_motors(tmp_path: Path, make_chain: ChainFactory) -> None:
    heights = []
    for motors in (1, 15):
        chain = make_chain(motors=motors)
        record(chain)
        for mid in chain.motor_ids:
            chain.set_param(mid, 34, 1)
            chain.execute(f"S.{mid}={10 * mid}, A.{mid}=100, P.{mid}={500 * mid}")
            chain.execute(f"^.{mid}")
        chain.kernel.run(until=seconds(1.5))
        path = plot_chain(chain, tmp_path / f"m{motors}.png", title=f"{motors} motors")
        heights.append(matplotlib.image.imread(path).shape[0])
    assert heights[1] > heights[0] * 1.5


@pytest.mark.parametrize("ux, name", [(0, "moving"), (8, "in position"), (16, "motor free"),
                                      (32, "push"), (40, "push complete"), (4, "alarm"),
                                      (512, "emergency stop"), (256, "moving")])
def test_6_6_status_classes_of_the_timeline(ux: int, name: str) -> None:
    assert status_class(ux) == name


# -- what a plot says: title, legend, output rows, the XY panel ----------------------------
def test_plot_with_an_unknown_extension_fails_before_the_run(tmp_path: Path) -> None:
    done = run_coolmuscle("run", str(EXAMPLES / "2.1-operation.cml"), "--plot",
                          str(tmp_path / "x.jpgx"))
    assert done.returncode == 2
    assert done.stdout == ""                                # nothing ran
    assert "cannot plot to" in done.stderr and ".png" in done.stderr
    assert "internal error" not in done.stderr


@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """Every figure saved during the test."""
    saved: list[Any] = []
    original = matplotlib.figure.Figure.savefig

    def keep(self: Any, *args: Any, **kwargs: Any) -> Any:
        saved.append(self)
        return original(self, *args, **kwargs)
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)
    return saved


def _legend_texts(fig: Any) -> set[str]:
    return {t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().texts}


def test_plot_title_legend_outputs_and_stopper(tmp_path: Path, figures: list[Any]) -> None:
    with pytest.raises(SystemExit) as info:
        cli.main(["run", str(EXAMPLES / "4.1.4-push-motion.cml"), "--plot",
                  str(tmp_path / "push.png")])
    assert info.value.code in (0, None)
    fig = figures[-1]
    assert fig._suptitle.get_text().startswith("4.1.4-push-motion.cml")
    legend = _legend_texts(fig)
    assert {"moving", "push", "push complete"} <= legend       # Ux 0, 32, 40 occur
    assert not legend & {"alarm", "emergency stop", "motor free"}
    timeline = fig.axes[-1]
    labels = [t.get_text() for t in timeline.get_yticklabels()]
    assert "status" in labels
    stoppers = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert any("stopper 11000" in t for t in stoppers)        # the pushed object


def test_plot_draws_the_stoppers_in_the_coordinates_of_each_instant(
        tmp_path: Path, figures: list[Any]) -> None:
    """An origin set (2.1.2 "|2") moves where positions count from, not the stoppers: the
    dotted stopper lines step there, and the position never crosses them (drawn in the
    end-of-run coordinates they stood at -3500 / 500 all along, crossed by the move to
    2500 before the origin set)."""
    machine = tmp_path / "slide.toml"
    machine.write_text("[[axis]]\n[axis.stoppers]\nccw = -1000\ncw = 3000\n")
    script = tmp_path / "origin.cml"
    script.write_text("S.1=100\nA.1=100\nP.1=2500\n^.1\n@until ^Ux\\.1=8$ 5\n@wait 0.5\n"
                      "|2.1\nP.1=-3000\n^.1\n@until ^Ux\\.1=8$ 5\n@wait 0.5\n")
    with pytest.raises(SystemExit) as info:
        cli.main(["run", str(script), "--machine", str(machine), "--plot",
                  str(tmp_path / "o.png")])
    assert info.value.code in (0, None)
    position = figures[-1].axes[0]
    shaft = next(line for line in position.get_lines() if line.get_label() == "ID1")
    walls = [line for line in position.get_lines() if line.get_linestyle() == ":"]
    assert len(walls) == 2
    lo, hi = sorted(walls, key=lambda line: line.get_ydata()[0])
    assert (lo.get_ydata()[0], hi.get_ydata()[0]) == (-1000, 3000)
    assert (lo.get_ydata()[-1], hi.get_ydata()[-1]) == (-3500, 500)
    assert list(shaft.get_xdata()) == list(lo.get_xdata())
    for p, a, b in zip(shaft.get_ydata(), lo.get_ydata(), hi.get_ydata()):
        assert a <= p <= b
    texts = [t.get_text() for t in position.texts]
    assert "stopper -1000 -> -3500 (machine file)" in texts


def test_plot_output_rows_name_their_k34_function(tmp_path: Path, figures: list[Any]) -> None:
    script = tmp_path / "out.cml"
    script.write_text("K34.1=31\nO2.1\nS.1=100\nA.1=100\nP.1=1000\n^.1\n@wait 1\n")
    with pytest.raises(SystemExit):
        cli.main(["run", str(script), "--plot", str(tmp_path / "o.png")])
    labels = [t.get_text() for t in figures[-1].axes[-1].get_yticklabels()]
    assert "OUT1 in-position" in labels and "OUT2 general" in labels


def test_xy_panel_draws_the_dashed_command_path(tmp_path: Path, figures: list[Any]) -> None:
    with pytest.raises(SystemExit):
        cli.main(["run", str(EXAMPLES / "4.4.1-circular-radius.cml"), "--plot",
                  str(tmp_path / "arc.png")])
    fig = figures[-1]
    xy = [ax for ax in fig.axes if "XY path" in ax.get_title()]
    assert len(xy) == 1 and "command dashed" in xy[0].get_title()
    dashed = [line for line in xy[0].get_lines() if line.get_linestyle() == "--"
              and len(line.get_xdata()) > 10]
    assert dashed and dashed[0].get_zorder() > 2                # drawn over the actual path
    assert "command" in _legend_texts(fig)
