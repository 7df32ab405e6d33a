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
from typing import TYPE_CHECKING, Iterable

from ..motor.signals.analog_output import output_volts
from ..motor.signals.io import OUT_ROTATION_PULSE, digit
from ..motor.status import ALARM_BITS, Ux
from ..sim.kernel import NS_PER_S

if TYPE_CHECKING:
    from ..chain.daisy import Chain
    from ..motor.motor import Motor

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

    def starts(self, history: list) -> list[int]:
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
    """A trace being recorded; :meth:`close` writes it (CSV, or Parquet for .parquet)."""

    def __init__(self, recorder: TraceRecorder, path: Path, step: float) -> None:
        self.recorder = recorder
        self.path = path
        self.step = step

    def close(self) -> Path:
        return self.recorder.write(self.path, self.step)


def trace(chain: "Chain", path: str | Path, step: float = 0.001) -> TraceFile:
    """Record ``chain`` from now on; ``close()`` on the handle writes ``path``: CSV, or
    Parquet for a ``.parquet`` path (``TraceFormatError`` at once when pyarrow is missing)."""
    check_trace_path(path)
    return TraceFile(record(chain), Path(path), step)


def _record_signals(motor: "Motor") -> None:
    """Keep the history of the position-derived signals and the analog input."""
    timeline = getattr(motor, "timeline", None)
    if timeline is not None:
        timeline.record(True)
    analog = getattr(motor, "analog_input", None)
    if analog is not None:
        analog.recording = True


def _append(times: list[int], values: list, now: int, value: object) -> None:
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
        if digit(k34, number) != OUT_ROTATION_PULSE:     # K34=7 at that instant
            continue
        port = signal if digit(k33, number) == 1 else not signal
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
