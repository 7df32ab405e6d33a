"""The page's traces: the chain's trace recorder, its rows and files, its plot (docs/web.md).

Recording is off until asked (the page's Record button, ``run --web``): the recorder
(:mod:`coolmuscle.tools.trace.recorder`) looks at every motor after every kernel event.
It keeps the last ``RECORD_WINDOW_S`` seconds of virtual time (:func:`forget_old`, run
every ``FORGET_EVERY_S`` wall seconds by the server): what came before is forgotten, so
memory stays bounded however long the page records (docs/web.md "Record and download").
A download samples it in the model's thread (:mod:`.downloads`) and the file is written
here from those rows in a worker thread: CSV as ``coolmuscle run --trace`` writes it, or
Parquet with typed columns.  The plot is the one of ``coolmuscle run --plot``
(:mod:`coolmuscle.tools.trace.plot`), sampled in the model's thread and drawn by
:func:`draw` in a worker thread.
"""

from __future__ import annotations

import csv
import importlib
import math
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ...chain import Chain
from ...device import Device
from ...needs import has_extra
from ...sim.kernel import NS_PER_S
from ..trace.recorder import INTEGER_FIELDS, TraceRecorder, record


def start_recording(device: Device) -> TraceRecorder | None:
    """The chain's trace recorder from now on, or None when the device is no chain."""
    if not isinstance(device, Chain):
        return None
    recorder = record(device)
    # matplotlib takes seconds to import: do it now, beside the loop, not at the
    # first plot request (which runs in the model's thread).  Not a daemon: a
    # daemon thread stopped at exit inside matplotlib's C++ extensions (Ctrl-C
    # right after the start) aborts the process ("terminate called without an
    # active exception", SIGABRT); the exit waits for the import instead.
    if has_extra("plot"):         # without it the page answers that the plot needs it
        threading.Thread(target=importlib.import_module, args=("coolmuscle.tools.trace.plot",),
                         name="coolmuscle-web-plot-import", daemon=False).start()
    return recorder


#: Virtual seconds of history the page's recording keeps.
RECORD_WINDOW_S = 3600.0
#: Wall seconds between two trims of the page's recording.
FORGET_EVERY_S = 60.0


def forget_old(recorder: TraceRecorder, window_s: float = RECORD_WINDOW_S) -> None:
    """Forget the recording before the last ``window_s`` virtual seconds: its start
    moves up to there (downloads begin at it).  The model's thread."""
    upto = recorder.feed.now - int(window_s * NS_PER_S)
    if upto <= recorder.start:
        return
    for trace in recorder.traces.values():
        trace.forget_before(upto)
    recorder.start = upto


def trace_rows(recorder: TraceRecorder, step: float,
               end: int) -> tuple[list[str], Iterator[list[float]]]:
    """The trace's column names and its rows up to ``end`` (ns), drawn lazily: the
    caller takes a few at a time in the model's thread."""
    return recorder.header(), iter(recorder.rows(step, end))


def write_rows(path: Path, header: list[str], rows: list[list[float]]) -> None:
    """CSV as ``coolmuscle run --trace`` writes it, or Parquet (typed columns) for
    ``.parquet``; touches no model state (any thread)."""
    if path.suffix == ".parquet":
        _write_parquet(path, header, rows)
        return
    with path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        for row in rows:
            writer.writerow([f"{row[0]:.9f}"] + [_cell(v) for v in row[1:]])


def plot_times(recorder: TraceRecorder) -> list[int]:
    """The instants the plot samples (the model's thread)."""
    from ..trace.plot import plot_times as times
    return times(recorder)


def sample_motors(recorder: TraceRecorder, times: list[int]) -> dict[int, list[Any]]:
    """Every motor's samples at ``times`` (the model's thread)."""
    from ..trace.plot import sample_motors as sample
    return sample(recorder, times)


def plot_facts(recorder: TraceRecorder, times: list[int],
               samples: dict[int, list[Any]]) -> Any:
    """What the plot draws, read from the recorder (the model's thread)."""
    from ..trace.plot import plot_facts as facts
    return facts(recorder, times, samples)


def draw(facts: Any, title: str) -> bytes:
    """The plot as PNG bytes, drawn from ``facts`` alone (any thread: a worker's)."""
    from ..trace.plot import draw_plot
    with tempfile.TemporaryDirectory(prefix="coolmuscle-web-") as tmp:
        path = Path(tmp) / "plot.png"
        draw_plot(facts, path, title)
        return path.read_bytes()


def _cell(value: float) -> str:
    """Integers without a point, infinities as ``inf``, others to 6 decimals."""
    if isinstance(value, float) and not math.isfinite(value):
        return "inf" if value > 0 else "-inf"
    if float(value).is_integer() and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.6f}"


def _write_parquet(path: Path, header: list[str], rows: list[list[float]]) -> None:
    import pyarrow as pa  # noqa: PLC0415  (optional)
    import pyarrow.parquet as pq  # noqa: PLC0415

    columns = list(zip(*rows)) if rows else [() for _ in header]
    arrays = {}
    for name, values in zip(header, columns):
        if name.rsplit(".", 1)[-1] in INTEGER_FIELDS:
            arrays[name] = pa.array([int(v) for v in values], type=pa.int64())
        else:
            arrays[name] = pa.array([float(v) for v in values], type=pa.float64())
    pq.write_table(pa.table(arrays), str(path))
