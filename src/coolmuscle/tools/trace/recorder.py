"""The trace recorder: time, target, position, speed, torque, status and I/O of every motor.

Motion is closed form, so the recorder does not tick: it keeps each axis's trajectory
history (every profile the axis followed, with its tracking solution) and the discrete
state (Ux, inputs, outputs) each time a kernel event changes it.  On export it samples
the history at any resolution, exactly, plus every discrete change.

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
from bisect import bisect_right
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable

from ...motor.signals.analog_output import output_volts
from ...motor.state.output_functions import OUT_ROTATION_PULSE
from ...motor.status import ALARM_BITS, Ux
from ...sim.kernel import NS_PER_S

if TYPE_CHECKING:
    from ...chain.daisy import Chain
    from ...motor.motor import Motor

#: Ux bits during which the motor makes no torque: motor free and the alarms.
_NO_TORQUE = int(Ux.MOTOR_FREE | ALARM_BITS)

FIELDS = ("target", "command", "position", "speed", "torque", "status", "inputs", "outputs",
          "analog_in", "analog_out", "encoder")

#: Most position-derived edges added to the sample times of one export.
MAX_EDGE_SAMPLES = 200_000

#: Columns holding whole numbers (Parquet int64); the others are float64.
INTEGER_FIELDS = frozenset({"status", "inputs", "outputs", "analog_in", "encoder"})


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


@dataclass(frozen=True, slots=True)
class Sample:
    """One motor's values at one instant."""

    time: int
    target: float
    command: float
    position: float
    speed: float
    torque: float
    status: int
    inputs: int
    outputs: int
    analog_in: int = 0
    analog_out: float = 2.5
    encoder: int = 0

    def row(self) -> tuple[float, ...]:
        return (self.target, self.command, self.position, self.speed, self.torque,
                self.status, self.inputs, self.outputs, self.analog_in, self.analog_out,
                self.encoder)


class _MotorLog:
    """Discrete-state changes of one motor: (time, status, inputs, outputs)."""

    def __init__(self, motor: "Motor") -> None:
        self.motor = motor
        self.times: list[int] = []
        self.states: list[tuple[int, int, int]] = []
        #: (time, (K33, K34, K35)) at each change: a sample uses the values of its time
        self.k_times: list[int] = []
        self.k_values: list[tuple[int, int, int]] = []
        self._starts: list[int] = []
        self.capture()

    def capture(self) -> None:
        m = self.motor
        ks = (m.k(33), m.k(34), m.k(35))
        if not self.k_values or self.k_values[-1] != ks:
            _append(self.k_times, self.k_values, m.kernel.now, ks)
        state = (m.status, m.io.input_word(), m.io.output_word())
        if not self.states or self.states[-1] != state:
            now = m.kernel.now
            if self.times and self.times[-1] == now:
                self.states[-1] = state
            else:
                self.times.append(now)
                self.states.append(state)

    def state_at(self, t: int) -> tuple[int, int, int]:
        i = bisect_right(self.times, t) - 1
        return self.states[max(i, 0)]

    def k_at(self, t: int) -> tuple[int, int, int]:
        """(K33, K34, K35) in force at ``t``."""
        return self.k_values[max(bisect_right(self.k_times, t) - 1, 0)]

    def starts(self, history: list[Any]) -> list[int]:
        """Start times of the axis history (cached; the history only grows)."""
        if len(self._starts) != len(history):
            self._starts = [h[0] for h in history]
        return self._starts


class TraceRecorder:
    """Records a chain from the moment it is attached; export with :meth:`samples`."""

    def __init__(self, chain: "Chain") -> None:
        self.chain = chain
        self.start = chain.kernel.now
        self._logs = {mid: _MotorLog(m) for mid, m in chain.motors.items()}
        for motor in chain.motors.values():
            motor.axis.record_history(True)
            _record_signals(motor)
            # a motion started from outside a kernel event (Python API) changes Ux too
            listeners = getattr(motor.axis, "trajectory_listeners", None)
            if listeners is not None:
                listeners.append(self.capture)
        self._remove = chain.kernel.add_observer(self.capture)
        self._unobserve = chain.observe(self.capture)

    def capture(self) -> None:
        """Note the discrete state of every motor now (called after each event)."""
        for log in self._logs.values():
            log.capture()

    def stop(self) -> None:
        """Stop recording discrete changes (the history is kept for export)."""
        self._remove()
        for log in self._logs.values():
            listeners = getattr(log.motor.axis, "trajectory_listeners", [])
            if self.capture in listeners:
                listeners.remove(self.capture)

    @property
    def motor_ids(self) -> tuple[int, ...]:
        return tuple(self._logs)

    def change_times(self, end: int | None = None) -> list[int]:
        """Every instant a discrete state, a trajectory or a pulse output changed."""
        end = self.chain.kernel.now if end is None else end
        times: set[int] = set()
        for log in self._logs.values():
            times.update(log.times)
            times.update(t for t, *_ in log.motor.axis.history or ())
            pulses = getattr(log.motor, "pulses", None)
            if pulses is not None:
                times.update(pulses.edge_times(self.start, end)[:MAX_EDGE_SAMPLES])
        return sorted(times)

    def sample(self, motor_id: int, t: int) -> Sample:
        """The values of ``motor_id`` at kernel time ``t`` (exact)."""
        log = self._logs[motor_id]
        motor = log.motor
        history = motor.axis.history or []
        starts = log.starts(history)
        i = max(bisect_right(starts, t) - 1, 0)
        _, profile, motion, zero, sign = history[i]
        command_raw = motion.command_at(t)
        actual_raw = motion.position_at(t)
        final = profile.final_position
        target = sign * (final - zero) if math.isfinite(final) else math.copysign(math.inf, final)
        speed = sign * motion.velocity_at(t)
        status, inputs, outputs = log.state_at(t)
        ppr = motor.resolution.pulses_per_rev
        torque = sign * motion.torque_percent_at(t)
        if not status & _NO_TORQUE:
            torque += _load(motor, t)
        command = sign * (command_raw - zero)
        position = sign * (actual_raw - zero)
        error = command_raw - actual_raw
        k33, k34, k35 = log.k_at(t)          # the K values of that instant, not of now
        analog_out = output_volts(k35, target=target if math.isfinite(target)
                                  else command, position=position, error=sign * error,
                                  speed_pps=speed, torque=torque, pulses_per_rev=ppr)
        return Sample(t, target, command, position, speed, torque, status, inputs,
                      _pulse_ports(motor, t, outputs, k33, k34),
                      _signal(motor, "analog_input", t), analog_out,
                      _signal(motor, "encoder", t))

    def times(self, step: float, end: int | None = None) -> list[int]:
        """A grid of ``step`` seconds from the start to ``end`` (default now), plus changes."""
        end = self.chain.kernel.now if end is None else end
        step_ns = max(int(step * NS_PER_S), 1)
        grid = set(range(self.start, end + 1, step_ns))
        grid.update(t for t in self.change_times(end) if self.start <= t <= end)
        grid.add(end)
        return sorted(grid)

    def rows(self, step: float = 0.001, end: int | None = None) -> Iterable[list[float]]:
        """Rows of ``time_s`` then FIELDS for each motor."""
        for t in self.times(step, end):
            row: list[float] = [t / NS_PER_S]
            for mid in self._logs:
                row.extend(self.sample(mid, t).row())
            yield row

    def header(self) -> list[str]:
        return ["time_s"] + [f"m{mid}.{f}" for mid in self._logs for f in FIELDS]

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


_RECORDERS: "weakref.WeakKeyDictionary[Chain, TraceRecorder]" = weakref.WeakKeyDictionary()


class NoTraceRecorderError(TraceFormatError):
    """A chain that cannot be recorded (not a :class:`~coolmuscle.chain.Chain`)."""


def record(chain: "Chain") -> TraceRecorder:
    """Start (or return) the trace recorder of ``chain``; it records from now on."""
    if not callable(getattr(chain, "observe", None)):
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
                 on_warning: "Callable[[str], None] | None" = None) -> None:
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


def trace(chain: "Chain", path: str | Path, step: float = 0.001, *,
          warn_bytes: int | None = None,
          on_warning: "Callable[[str], None] | None" = None) -> TraceFile:
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
                 on_warning: "Callable[[str], None] | None" = None) -> None:
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
        kernel = recorder.chain.kernel
        self._remove = kernel.add_observer(self._on_event)
        self._unobserve = recorder.chain.observe(self._on_event)

    # -- driving ----------------------------------------------------------------------
    def _on_event(self) -> None:
        if self._busy or self._closed:
            return
        now = self.recorder.chain.kernel.now
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
            self._write_until(self.recorder.chain.kernel.now, inclusive=True)
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
        rec = self.recorder
        for mid, log in rec._logs.items():
            a, b = rec.sample(mid, t0).row(), rec.sample(mid, t1).row()
            if a != b or (self._last is not None and self._last_of(mid) != a):
                return False
            history = log.motor.axis.history or []
            if history:
                starts = log.starts(history)
                entry = history[max(bisect_right(starts, t0) - 1, 0)]
                piece = _piece(entry)
                if piece is not None and piece.turns(t0, t1):
                    return False
        return True

    def _last_of(self, motor_id: int) -> tuple[float, ...] | None:
        if self._last is None:
            return None
        return self._last[list(self.recorder._logs).index(motor_id)]

    def _row(self, t: int) -> None:
        rec = self.recorder
        samples = [rec.sample(mid, t).row() for mid in rec._logs]
        self._last = samples
        self._last_t = t
        row: list[float] = [t / NS_PER_S]
        for values in samples:
            row.extend(values)
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
        for log in self.recorder._logs.values():
            times.update(t for t in log.times if t >= a)
            times.update(t for t, *_ in log.motor.axis.history or () if t >= a)
            pulses = getattr(log.motor, "pulses", None)
            if pulses is not None and end > a:
                times.update(pulses.edge_times(a, end)[:MAX_EDGE_SAMPLES])
            analog = getattr(log.motor, "analog_input", None)
            if analog is not None:
                times.update(t for t in analog.since if t >= a)
        return times

    # -- bounded memory ---------------------------------------------------------------
    def _prune(self, upto: int) -> None:
        """Forget what only rows before ``upto`` needed (keep what covers ``upto``)."""
        for log in self.recorder._logs.values():
            _trim_pairs(log.times, log.states, upto)
            history = log.motor.axis.history
            if history:
                starts = [h[0] for h in history]
                i = bisect_right(starts, upto) - 1
                if i > 0:
                    del history[:i]
                    log._starts = []
            analog = getattr(log.motor, "analog_input", None)
            if analog is not None and analog.recording:
                _trim_pairs(analog.since, analog.sources, upto)
            timeline = getattr(log.motor, "timeline", None)
            for track in getattr(timeline, "tracks", ()):
                _trim_pairs(track._times, track.checkpoints, upto)

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


def _trim_pairs(times: list[int], values: list[Any], upto: int) -> None:
    """Drop the entries of two parallel lists before the last one at or before ``upto``."""
    i = bisect_right(times, upto) - 1
    if i > 0:
        del times[:i]
        del values[:i]


def _piece(entry: tuple[Any, ...]) -> Any:
    from ...motor.motion.trajectory import Piece  # noqa: PLC0415  (sampling helper)
    try:
        return Piece(*entry)
    except TypeError:
        return None


def _record_signals(motor: "Motor") -> None:
    """Keep the history of the position-derived signals and the analog input."""
    timeline = getattr(motor, "timeline", None)
    if timeline is not None:
        timeline.record(True)
    analog = getattr(motor, "analog_input", None)
    if analog is not None:
        analog.recording = True


def _append(times: list[int], values: list[Any], now: int, value: object) -> None:
    """Append a change at ``now`` (a second change at the same instant replaces it)."""
    if times and times[-1] == now:
        values[-1] = value
    else:
        times.append(now)
        values.append(value)


def _pulse_ports(motor: "Motor", t: int, outputs: int, k33: int, k34: int) -> int:
    """The output word at ``t`` with the rotation pulse ports (K34=7, K33 of that
    instant) filled in."""
    pulses = getattr(motor, "pulses", None)
    if pulses is None:
        return outputs
    for number, signal in pulses.signals_at(t).items():
        if motor.io.output_function(number, k34) != OUT_ROTATION_PULSE:   # at that instant
            continue
        port = motor.io.port_of(number, signal, k33)
        bit = 1 << (number - 1)
        outputs = (outputs | bit) if port else (outputs & ~bit)
    return outputs


def _load(motor: "Motor", t: int) -> float:
    """Torque (%) a sensed load (analog torque-sensor source, 5.5) takes at ``t``."""
    control = getattr(motor, "analog_control", None)
    return control.load_percent(t) if control is not None else 0.0


def _signal(motor: "Motor", name: str, t: int) -> int:
    """Analog input counts or encoder count at ``t`` (0 for a motor without them)."""
    source = getattr(motor, name, None)
    if source is None:
        return 0
    return int(source.counts(t) if name == "analog_input" else source.count(t))


def _fmt(value: float) -> str:
    if isinstance(value, int) or (isinstance(value, float) and value.is_integer()
                                  and abs(value) < 1e15):
        return str(int(value))
    if isinstance(value, float) and not math.isfinite(value):
        return "inf" if value > 0 else "-inf"
    return f"{value:.6f}"
