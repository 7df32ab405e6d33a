"""The trace recorder: time, target, position, speed, torque, status and I/O of every motor.

Motion is closed form, so the recorder does not tick: it reads the device API's trace
feed (:meth:`coolmuscle.device.api.Device.trace_feed`, :mod:`coolmuscle.device.trace`),
which keeps each axis's trajectory history (every profile the axis followed, with its
tracking solution) and the discrete state (Ux, inputs, outputs) each time it may have
changed, and samples them exactly at any instant.  On export the recorder samples at
any resolution, plus every change; it reads nothing of the motors but the feed.

Columns (per motor ``m<ID>.``): ``target``, ``command``, ``position`` (pulses),
``speed`` (actual, pulses/s), ``torque`` (% rated), ``status`` (Ux), ``inputs``,
``outputs`` (words, bit 0 = number 1, as the ports read: K33 applied),
``analog_in`` (converter counts 0..1023, ?74), ``analog_out`` (volts, K35) and
``encoder`` (external encoder count, ?76).

Outputs that are functions of the position (rotation pulses, K34=7) change between
events: they are evaluated at each sample instant and their solved edge instants
are added to the sample times, so a trace shows every edge exactly.  Export:
:meth:`TraceRecorder.write` (CSV, or Parquet when pyarrow is installed).
"""

from __future__ import annotations

import csv
import importlib.util
import math
import weakref
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from ...device.api import Device
from ...device.trace import MotorTrace, TraceFeed, TraceSample
from ...sim.kernel import NS_PER_S

#: One motor's values at one instant (:class:`coolmuscle.device.trace.TraceSample`).
Sample = TraceSample

FIELDS = ("target", "command", "position", "speed", "torque", "status", "inputs", "outputs",
          "analog_in", "analog_out", "encoder")

#: Most position-derived edges added to the sample times of one export.
MAX_EDGE_SAMPLES = 200_000

#: Columns holding whole numbers (Parquet int64); the others are float64.
INTEGER_FIELDS = frozenset({"status", "inputs", "outputs", "analog_in", "encoder", "wire"})


class TraceFormatError(ValueError):
    """A trace path the recorder cannot write (Parquet without pyarrow)."""


def parquet_available() -> bool:
    """Whether pyarrow is installed (Parquet traces are optional)."""
    return importlib.util.find_spec("pyarrow") is not None


def check_trace_path(path: str | Path) -> None:
    """Refuse, before anything runs, a trace the recorder could not write."""
    if Path(path).suffix.lower() == ".parquet" and not parquet_available():
        raise TraceFormatError(f"cannot write {path}: Parquet traces need pyarrow "
                               "(pip install pyarrow); a .csv path needs nothing")


class TraceRecorder:
    """Records a chain from the moment it is attached (through the device API's trace
    feed, :meth:`coolmuscle.device.api.Device.trace_feed`); export with :meth:`samples`."""

    def __init__(self, chain: Device) -> None:
        self.chain = chain
        self.feed: TraceFeed = chain.trace_feed()
        self.start = self.feed.start
        #: Each motor's recording, by ID (the feed's).
        self.traces: dict[int, MotorTrace] = self.feed.traces

    def capture(self) -> None:
        """Note the discrete state of every motor now (the feed does it after each event)."""
        self.feed.capture()

    def stop(self) -> None:
        """Stop recording discrete changes (the history is kept for export)."""
        self.feed.stop()

    @property
    def motor_ids(self) -> tuple[int, ...]:
        return tuple(self.traces)

    def change_times(self, end: int | None = None) -> list[int]:
        """Every instant a discrete state, a trajectory or a pulse output changed."""
        end = self.feed.now if end is None else end
        times: set[int] = set()
        for trace in self.traces.values():
            times.update(trace.state_times())
            times.update(trace.piece_starts())
            times.update(trace.pulse_edges(self.start, end)[:MAX_EDGE_SAMPLES])
        times.update(self.feed.wire_times())
        return sorted(times)

    def sample(self, motor_id: int, t: int) -> Sample:
        """The values of ``motor_id`` at kernel time ``t`` (exact)."""
        return self.traces[motor_id].sample(t)

    def times(self, step: float, end: int | None = None) -> list[int]:
        """A grid of ``step`` seconds from the start to ``end`` (default now), plus changes."""
        end = self.feed.now if end is None else end
        step_ns = max(int(step * NS_PER_S), 1)
        grid = set(range(self.start, end + 1, step_ns))
        grid.update(t for t in self.change_times(end) if self.start <= t <= end)
        grid.add(end)
        return sorted(grid)

    def rows(self, step: float = 0.001, end: int | None = None) -> Iterable[list[float]]:
        """Rows of ``time_s`` then FIELDS for each motor."""
        for t in self.times(step, end):
            row: list[float] = [t / NS_PER_S]
            for trace in self.traces.values():
                row.extend(trace.sample(t).row())
            if self.feed.wire_column:
                row.append(self.feed.wire_count(t))
            yield row

    def header(self) -> list[str]:
        """``time_s``, each motor's FIELDS, and ``wire`` (what the wire faults did so
        far, docs/wire-faults.md) when a wire fault was installed as recording began."""
        wire = ["wire"] if self.feed.wire_column else []
        return ["time_s"] + [f"m{mid}.{f}" for mid in self.traces for f in FIELDS] + wire

    def write(self, path: str | Path, step: float = 0.001) -> Path:
        """Write the trace: Parquet for a ``.parquet`` path (pyarrow), else CSV."""
        if Path(path).suffix.lower() == ".parquet":
            return self.write_parquet(path, step)
        return self.write_csv(path, step)

    def write_parquet(self, path: str | Path, step: float = 0.001) -> Path:
        """Write the trace as Parquet (needs pyarrow: :class:`TraceFormatError`)."""
        check_trace_path(path)
        import pyarrow as pa  # noqa: PLC0415  (optional dependency)
        import pyarrow.parquet as pq  # noqa: PLC0415
        header = self.header()
        columns: list[list[float]] = [[] for _ in header]
        for row in self.rows(step):
            for column, value in zip(columns, row):
                column.append(value)
        arrays = {}
        for name, values in zip(header, columns):
            if name.rsplit(".", 1)[-1] in INTEGER_FIELDS:
                arrays[name] = pa.array([int(v) for v in values], type=pa.int64())
            else:
                arrays[name] = pa.array(values, type=pa.float64())
        path = Path(path)
        pq.write_table(pa.table(arrays), str(path))
        return path

    def write_csv(self, path: str | Path, step: float = 0.001) -> Path:
        """Write the trace as CSV (``step`` seconds between grid samples; times to the ns)."""
        path = Path(path)
        with path.open("w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(self.header())
            for row in self.rows(step):
                writer.writerow([f"{row[0]:.9f}"] + [_fmt(v) for v in row[1:]])
        return path


_RECORDERS: weakref.WeakKeyDictionary[Device, TraceRecorder] = weakref.WeakKeyDictionary()


class NoTraceRecorderError(TraceFormatError):
    """A chain that cannot be recorded (no trace feed: not a :class:`~coolmuscle.device.Device`)."""


def record(chain: Device) -> TraceRecorder:
    """Start (or return) the trace recorder of ``chain``; it records from now on."""
    if not callable(getattr(chain, "trace_feed", None)):
        raise NoTraceRecorderError(f"this chain ({type(chain).__name__}) has no trace recorder")
    recorder = _RECORDERS.get(chain)
    if recorder is None:
        recorder = _RECORDERS[chain] = TraceRecorder(chain)
    return recorder


class TraceFile:
    """A trace written to its file as the run goes (see :class:`TraceStream`);
    :meth:`close` writes the rows up to now and closes it, :meth:`abort` closes it
    at once (Ctrl-C): either way the file is complete and valid up to its last row."""

    def __init__(self, recorder: TraceRecorder, path: Path, step: float, *,
                 prune: bool = True, warn_bytes: int | None = None,
                 on_warning: Callable[[str], None] | None = None) -> None:
        self.recorder = recorder
        self.path = path
        self.step = step
        self.stream = TraceStream(recorder, path, step, prune=prune, warn_bytes=warn_bytes,
                                  on_warning=on_warning)

    def close(self) -> Path:
        self.stream.close()
        return self.path

    def abort(self) -> Path:
        self.stream.abort()
        return self.path


def trace(chain: Device, path: str | Path, step: float = 0.001, *,
          warn_bytes: int | None = None,
          on_warning: Callable[[str], None] | None = None) -> TraceFile:
    """Record ``chain`` from now on into ``path`` (CSV, or Parquet for ``.parquet``:
    ``TraceFormatError`` at once when pyarrow is missing), streamed as the run goes;
    ``close()`` on the handle finishes it.  ``warn_bytes``: call ``on_warning`` once
    when the file passes that size."""
    check_trace_path(path)
    if not step > 0:
        raise TraceFormatError(f"the trace step must be > 0 s, not {step!r}")
    shared = chain in _RECORDERS     # someone else (a plot) reads the whole history
    return TraceFile(record(chain), Path(path), step, prune=not shared,
                     warn_bytes=warn_bytes, on_warning=on_warning)


#: Virtual time between two flushes of a streamed trace.
FLUSH_NS = NS_PER_S // 2
#: Grid stretch checked at once for a motor at rest (see TraceStream).
REST_CHUNK_NS = NS_PER_S
#: Rows per Parquet row group.
PARQUET_ROWS = 65536
#: Default size after which a trace warns once (docs/scripts.md "traces").
DEFAULT_WARN_BYTES = 100 * 1024 * 1024


class TraceStream:
    """Rows written as virtual time passes, with bounded memory.

    Each kernel event (and each API change) lets the stream write every row
    before now: the grid of ``step`` seconds plus every change instant (a new
    trajectory, Ux, inputs, outputs, pulse edges).  A row is never revised: the
    closed-form history fixes everything before now.  What is written is
    forgotten (the axis history, the discrete logs, pulse checkpoints and analog
    sources before it), so memory does not grow with the run's length.

    Change recording: while every motor is at rest (equal values at both ends of
    a stretch and no turning point of the position between), the grid rows of
    that stretch are left out; the values hold until the next row, exactly.
    """

    def __init__(self, recorder: TraceRecorder, path: Path, step: float, *,
                 prune: bool = True, warn_bytes: int | None = None,
                 on_warning: Callable[[str], None] | None = None) -> None:
        self.recorder = recorder
        self.path = Path(path)
        self.step_ns = max(int(round(step * NS_PER_S)), 1)
        self.prune = prune
        self.warn_bytes = warn_bytes
        self.on_warning = on_warning
        self.next_t = recorder.start      # rows before this instant are written
        self.rows_written = 0
        self.bytes_written = 0
        self._warned = False
        self._last: list[tuple[float, ...]] | None = None
        self._last_t: int | None = None
        self._closed = False
        self._busy = False
        self._parquet = self.path.suffix.lower() == ".parquet"
        self._columns: list[list[float]] = []
        self._pq_writer: Any = None
        self._fh: Any = None
        self._csv: Any = None
        header = recorder.header()
        if self._parquet:
            self._columns = [[] for _ in header]
        else:
            self._fh = self.path.open("w", newline="")
            self._csv = csv.writer(self._fh)
            self._csv.writerow(header)
        kernel = self._kernel = recorder.chain.kernel
        self._remove = kernel.add_observer(self._on_event)
        self._unobserve = recorder.chain.observe(self._on_event)

    # -- driving ----------------------------------------------------------------------
    def _on_event(self) -> None:
        if self._busy or self._closed:
            return
        now = self._kernel.now
        if now - self.next_t >= FLUSH_NS:
            self._busy = True
            try:
                self.recorder.capture()
                self._write_until(now, inclusive=False)
            finally:
                self._busy = False

    def close(self) -> None:
        """Write the rows up to now (the last instant included) and close the file."""
        if self._closed:
            return
        try:
            self.recorder.capture()
            self._write_until(self._kernel.now, inclusive=True)
        finally:
            self._finish()

    def abort(self) -> None:
        """Close the file now with the rows written so far (Ctrl-C)."""
        if not self._closed:
            self._finish()

    def _finish(self) -> None:
        self._closed = True
        self._remove()
        self._unobserve()
        if self._parquet:
            self._flush_parquet(final=True)
        elif self._fh is not None:
            self._fh.close()

    # -- rows -------------------------------------------------------------------------
    def _write_until(self, end: int, *, inclusive: bool) -> None:
        rec = self.recorder
        a = self.next_t
        stop = end + 1 if inclusive else end
        if stop <= a:
            return
        changes = sorted(t for t in self._changes(a, end) if a <= t < stop)
        first_is_change = bool(changes) and changes[0] == a
        cuts = [a, *(c for c in changes if c != a), stop]
        for i, (c0, c1) in enumerate(zip(cuts, cuts[1:])):
            if i == 0 and not first_is_change and a != rec.start:
                self._grid(c0, c1)          # a flush boundary: only grid rows from here
                continue
            self._row(c0)
            self._grid(c0 + 1, c1)
        if inclusive and self._last_t != end:
            self._row(end)
        self.next_t = stop
        if self.prune:
            self._prune(stop - 1)
        if self._parquet:
            self._flush_parquet()
        elif self._fh is not None:
            self._fh.flush()
        self._check_size()

    def _grid(self, lo: int, c1: int) -> None:
        """Grid rows at ``lo <= t < c1``, skipping stretches at rest."""
        start, step = self.recorder.start, self.step_ns
        k = -(-(lo - start) // step)
        t = start + k * step
        span = REST_CHUNK_NS
        while t < c1:
            chunk_end = min(c1, t + span)
            if self._at_rest(t, chunk_end - 1):
                k = (chunk_end - 1 - start) // step + 1
                t = start + k * step
                span *= 2                  # at rest: try a longer stretch next
                continue
            if span > REST_CHUNK_NS:       # a long stretch failed: look closer
                span = REST_CHUNK_NS
                continue
            while t < chunk_end:
                self._row(t)
                t += step

    def _at_rest(self, t0: int, t1: int) -> bool:
        if t1 <= t0:
            return False
        for i, trace in enumerate(self.recorder.traces.values()):
            a, b = trace.sample(t0).row(), trace.sample(t1).row()
            if a != b or (self._last is not None and self._last[i] != a):
                return False
            if trace.turns(t0, t1):
                return False
        return True

    def _row(self, t: int) -> None:
        samples = [trace.sample(t).row() for trace in self.recorder.traces.values()]
        self._last = samples
        self._last_t = t
        row: list[float] = [t / NS_PER_S]
        for values in samples:
            row.extend(values)
        feed = self.recorder.feed
        if feed.wire_column:
            row.append(feed.wire_count(t))
        self.rows_written += 1
        if self._parquet:
            for column, value in zip(self._columns, row):
                column.append(value)
            self.bytes_written += 8 * len(row)
        else:
            self._csv.writerow([f"{row[0]:.9f}"] + [_fmt(v) for v in row[1:]])

    def _check_size(self) -> None:
        if self._fh is not None:
            self.bytes_written = self._fh.tell()
        if (self.warn_bytes is not None and not self._warned
                and self.bytes_written > self.warn_bytes):
            self._warned = True
            if self.on_warning is not None:
                size = (f"{self.warn_bytes / (1 << 20):g} MB" if self.warn_bytes >= 1 << 20
                        else f"{self.warn_bytes} bytes")
                self.on_warning(f"trace {self.path} passed {size} at virtual "
                                f"{self.next_t / NS_PER_S:.3f} s; a larger --trace-step "
                                "makes it smaller")

    def _changes(self, a: int, end: int) -> set[int]:
        times: set[int] = set()
        for trace in self.recorder.traces.values():
            times.update(t for t in trace.state_times() if t >= a)
            times.update(t for t in trace.piece_starts() if t >= a)
            if end > a:
                times.update(trace.pulse_edges(a, end)[:MAX_EDGE_SAMPLES])
            times.update(t for t in trace.analog_times() if t >= a)
        times.update(t for t in self.recorder.feed.wire_times() if t >= a)
        return times

    # -- bounded memory ---------------------------------------------------------------
    def _prune(self, upto: int) -> None:
        """Forget what only rows before ``upto`` needed (keep what covers ``upto``)."""
        for trace in self.recorder.traces.values():
            trace.forget_before(upto)
        self.recorder.feed.forget_wire_before(upto)

    def _flush_parquet(self, final: bool = False) -> None:
        if not final and len(self._columns[0]) < PARQUET_ROWS:
            return
        import pyarrow as pa  # noqa: PLC0415  (optional dependency)
        import pyarrow.parquet as pq  # noqa: PLC0415
        header = self.recorder.header()
        arrays = {}
        for name, values in zip(header, self._columns):
            if name.rsplit(".", 1)[-1] in INTEGER_FIELDS:
                arrays[name] = pa.array([int(v) for v in values], type=pa.int64())
            else:
                arrays[name] = pa.array(values, type=pa.float64())
        table = pa.table(arrays)
        writer_class = getattr(pq, "ParquetWriter", None)
        if writer_class is None:          # a minimal pyarrow: one table at the end
            if final:
                pq.write_table(table, str(self.path))
            return
        if self._pq_writer is None:
            self._pq_writer = writer_class(str(self.path), table.schema)
        if len(self._columns[0]):
            self._pq_writer.write_table(table)
        self._columns = [[] for _ in header]
        if final:
            self._pq_writer.close()


def _fmt(value: float) -> str:
    if isinstance(value, int) or (isinstance(value, float) and value.is_integer()
                                  and abs(value) < 1e15):
        return str(int(value))
    if isinstance(value, float) and not math.isfinite(value):
        return "inf" if value > 0 else "-inf"
    return f"{value:.6f}"
