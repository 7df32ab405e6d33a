"""The trace recorder: time, target, position, speed, torque, status and I/O of every motor.

Motion is closed form, so the recorder does not tick: it keeps each axis's trajectory
history (every profile the axis followed, with its tracking solution) and the discrete
state (Ux, inputs, outputs) each time a kernel event changes it.  On export it samples
the history at any resolution, exactly, plus every discrete change.

Columns (per motor ``m<ID>.``): ``target``, ``command``, ``position`` (pulses),
``speed`` (actual, pulses/s), ``torque`` (% rated), ``status`` (Ux), ``inputs``,
``outputs`` (words, bit 0 = number 1).
"""

from __future__ import annotations

import csv
import math
from bisect import bisect_right
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterable

from .kernel import NS_PER_S

if TYPE_CHECKING:
    from ..chain import Chain
    from ..motor.motor import Motor

FIELDS = ("target", "command", "position", "speed", "torque", "status", "inputs", "outputs")


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

    def row(self) -> tuple[float, ...]:
        return (self.target, self.command, self.position, self.speed, self.torque,
                self.status, self.inputs, self.outputs)


class _MotorLog:
    """Discrete-state changes of one motor: (time, status, inputs, outputs)."""

    def __init__(self, motor: "Motor") -> None:
        self.motor = motor
        self.times: list[int] = []
        self.states: list[tuple[int, int, int]] = []
        self.capture()

    def capture(self) -> None:
        m = self.motor
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


class TraceRecorder:
    """Records a chain from the moment it is attached; export with :meth:`samples`."""

    def __init__(self, chain: "Chain") -> None:
        self.chain = chain
        self.start = chain.kernel.now
        self._logs = {mid: _MotorLog(m) for mid, m in chain.motors.items()}
        for motor in chain.motors.values():
            motor.axis.record_history(True)
        self._remove = chain.kernel.add_observer(self.capture)

    def capture(self) -> None:
        """Note the discrete state of every motor now (called after each event)."""
        for log in self._logs.values():
            log.capture()

    def stop(self) -> None:
        """Stop recording discrete changes (the history is kept for export)."""
        self._remove()

    @property
    def motor_ids(self) -> tuple[int, ...]:
        return tuple(self._logs)

    def change_times(self) -> list[int]:
        """Every instant a discrete state or a trajectory changed."""
        times: set[int] = set()
        for mid, log in self._logs.items():
            times.update(log.times)
            times.update(t for t, *_ in log.motor.axis.history or ())
        return sorted(times)

    def sample(self, motor_id: int, t: int) -> Sample:
        """The values of ``motor_id`` at kernel time ``t`` (exact)."""
        log = self._logs[motor_id]
        motor = log.motor
        history = motor.axis.history or []
        starts = [h[0] for h in history]
        i = max(bisect_right(starts, t) - 1, 0)
        _, profile, motion, zero, sign = history[i]
        command_raw = motion.command_at(t)
        actual_raw = motion.position_at(t)
        final = profile.final_position
        target = sign * (final - zero) if math.isfinite(final) else math.copysign(math.inf, final)
        speed = sign * motion.velocity_at(t)
        status, inputs, outputs = log.state_at(t)
        torque = sign * motion.torque_percent_at(t)
        return Sample(t, target, sign * (command_raw - zero), sign * (actual_raw - zero),
                      speed, torque, status, inputs, outputs)

    def times(self, step: float, end: int | None = None) -> list[int]:
        """A grid of ``step`` seconds from the start to ``end`` (default now), plus changes."""
        end = self.chain.kernel.now if end is None else end
        step_ns = max(int(step * NS_PER_S), 1)
        grid = set(range(self.start, end + 1, step_ns))
        grid.update(t for t in self.change_times() if self.start <= t <= end)
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

    def write_csv(self, path: str | Path, step: float = 0.001) -> Path:
        """Write the trace as CSV (``step`` seconds between grid samples)."""
        path = Path(path)
        with path.open("w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(self.header())
            for row in self.rows(step):
                writer.writerow([_fmt(v) for v in row])
        return path


def _fmt(value: float) -> str:
    if isinstance(value, int) or (isinstance(value, float) and value.is_integer()
                                  and abs(value) < 1e15):
        return str(int(value))
    if isinstance(value, float) and not math.isfinite(value):
        return "inf" if value > 0 else "-inf"
    return f"{value:.6f}"
