"""The trace feed: what a trace recorder reads of every motor, exact at any past instant.

Motion is closed form, so the feed does not tick.  From the moment it opens
(:meth:`coolmuscle.device.api.Device.trace_feed`) it keeps, for each motor:

* the trajectory history of its axis: every command profile it followed with the
  servo model's tracking solution, its start and the user coordinates then (``|2``
  may move the origin, K36 the direction);
* the discrete state (Ux, the input and output words of 6.6 ``?99``/``?70``/``?50``)
  and K33/K34/K35 (how the ports read, what the outputs do, what the analog output
  says: ch. 3) each time they may have changed: after each kernel event, each call
  through the device API and each new trajectory;
* the checkpoints of the signals that are functions of the position (rotation pulses
  K34=7, the external encoder) and the sources that drove the analog input.

:meth:`MotorTrace.sample` evaluates all of it at any instant since the feed opened,
exactly (:class:`TraceSample`); :meth:`MotorTrace.state_times`,
:meth:`MotorTrace.piece_starts`, :meth:`MotorTrace.pulse_edges` and
:meth:`MotorTrace.analog_times` say when something changed, so a trace can have a row
at every change.  The feed is read-only: it changes nothing of the motors, and what it
recorded it can forget (:meth:`MotorTrace.forget_before`), so a trace streamed to a file
keeps bounded memory.  The trace recorder (coolmuscle.tools.trace) reads only this.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..motor.motion.axis import wrap_user
from ..motor.motion.trajectory import Piece
from ..motor.signals.analog_output import output_volts
from ..motor.state.output_functions import OUT_ROTATION_PULSE
from ..motor.status import ALARM_BITS, Ux
from ..sim.kernel import Kernel

if TYPE_CHECKING:
    from ..motor.motor import Motor
    from .wire.schedule import WireFaults, WireRecord

#: Ux bits during which the motor makes no torque: motor free and the alarms.
_NO_TORQUE = int(Ux.MOTOR_FREE | ALARM_BITS)

#: Registers a callback called when state may change outside a kernel event; returns
#: its remover (:meth:`coolmuscle.device.api.Device.observe`).
Observe = Callable[[Callable[[], None]], Callable[[], None]]


@dataclass(frozen=True, slots=True)
class TraceSample:
    """One motor's values at one instant.

    ``target``, ``command`` and ``position`` in user pulses (``target`` is infinite
    while the motor turns continuously), ``speed`` actual, pulses/s, ``torque`` % of
    rated, ``status`` Ux, ``inputs``/``outputs`` words as the ports read (bit 0 = number
    1, K33 applied, rotation pulses included), ``analog_in`` converter counts 0..1023
    (?74), ``analog_out`` volts (K35) and ``encoder`` the external encoder count (?76).
    """

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
        """The values after ``time``, in the order of the fields."""
        return (self.target, self.command, self.position, self.speed, self.torque,
                self.status, self.inputs, self.outputs, self.analog_in, self.analog_out,
                self.encoder)


class MotorTrace:
    """The recording of one motor (see the module docstring); built by :class:`TraceFeed`."""

    def __init__(self, motor: Motor) -> None:
        self._motor = motor
        self.id = motor.id
        self._times: list[int] = []
        self._states: list[tuple[int, int, int]] = []
        #: (time, (K33, K34, K35)) at each change: a sample uses the values of its time
        self._k_times: list[int] = []
        self._k_values: list[tuple[int, int, int]] = []
        self._starts: list[int] = []
        self.capture()

    def _record(self, on_trajectory: Callable[[], None]) -> None:
        """Start keeping the history and the signals' checkpoints."""
        motor = self._motor
        motor.axis.record_history(True)
        motor.timeline.record(True)
        motor.analog_input.recording = True
        # a motion started from outside a kernel event (Python API) changes Ux too
        motor.axis.trajectory_listeners.append(on_trajectory)

    def _unlisten(self, on_trajectory: Callable[[], None]) -> None:
        listeners = self._motor.axis.trajectory_listeners
        if on_trajectory in listeners:
            listeners.remove(on_trajectory)

    # -- recording ------------------------------------------------------------------
    def capture(self) -> None:
        """Note the discrete state now (the feed calls it after every change)."""
        m = self._motor
        ks = (m.k(33), m.k(34), m.k(35))
        if not self._k_values or self._k_values[-1] != ks:
            _append(self._k_times, self._k_values, m.kernel.now, ks)
        state = (m.status, m.io.input_word(), m.io.output_word())
        if not self._states or self._states[-1] != state:
            now = m.kernel.now
            if self._times and self._times[-1] == now:
                self._states[-1] = state
            else:
                self._times.append(now)
                self._states.append(state)

    def forget_before(self, upto: int) -> None:
        """Forget what only instants before ``upto`` need (keep what covers ``upto``)."""
        _trim_pairs(self._times, self._states, upto)
        motor = self._motor
        history = motor.axis.history
        if history:
            starts = [h[0] for h in history]
            i = bisect_right(starts, upto) - 1
            if i > 0:
                del history[:i]
                self._starts = []
        analog = motor.analog_input
        if analog.recording:
            _trim_pairs(analog.since, analog.sources, upto)
        for track in motor.timeline.tracks:
            _trim_pairs(track._times, track.checkpoints, upto)

    # -- when things changed ----------------------------------------------------------
    def state_times(self) -> Sequence[int]:
        """Instants the discrete state changed (ascending; read-only)."""
        return self._times

    def piece_starts(self) -> Sequence[int]:
        """Instants a new trajectory started (ascending; read-only)."""
        return self._piece_starts(self._motor.axis.history or [])

    def pulse_edges(self, t0: int, t1: int) -> list[int]:
        """The solved edges of the rotation pulse outputs (K34=7) in ``[t0, t1]``."""
        return self._motor.pulses.edge_times(t0, t1)

    def analog_times(self) -> Sequence[int]:
        """Instants another source started driving the analog input (read-only)."""
        return self._motor.analog_input.since

    def _piece_starts(self, history: Sequence[tuple[int, Any, Any, float, int]]) -> list[int]:
        """Start times of the axis history (cached; the history only grows)."""
        if len(self._starts) != len(history):
            self._starts = [h[0] for h in history]
        return self._starts

    # -- values at an instant -----------------------------------------------------------
    def state_at(self, t: int) -> tuple[int, int, int]:
        """(Ux, input word, output word) in force at ``t``."""
        i = bisect_right(self._times, t) - 1
        return self._states[max(i, 0)]

    def k_at(self, t: int) -> tuple[int, int, int]:
        """(K33, K34, K35) in force at ``t``."""
        return self._k_values[max(bisect_right(self._k_times, t) - 1, 0)]

    def sample(self, t: int) -> TraceSample:
        """The values at kernel time ``t`` (exact)."""
        motor = self._motor
        history = motor.axis.history or []
        starts = self._piece_starts(history)
        i = max(bisect_right(starts, t) - 1, 0)
        _, profile, motion, zero, sign = history[i]
        command_raw = motion.command_at(t)
        actual_raw = motion.position_at(t)
        final = profile.final_position
        target = sign * (final - zero) if math.isfinite(final) else math.copysign(math.inf, final)
        speed = sign * motion.velocity_at(t)
        status, inputs, outputs = self.state_at(t)
        ppr = motor.resolution.pulses_per_rev
        torque = sign * motion.torque_percent_at(t)
        if not status & _NO_TORQUE:
            torque += motor.analog_control.load_percent(t)   # a sensed load (5.5)
        half = motor.axis.half_range                 # as the position counter shows them
        command = wrap_user(sign * (command_raw - zero), half)
        position = wrap_user(sign * (actual_raw - zero), half)
        error = command_raw - actual_raw
        k33, k34, k35 = self.k_at(t)          # the K values of that instant, not of now
        analog_out = output_volts(k35, target=target if math.isfinite(target)
                                  else command, position=position, error=sign * error,
                                  speed_pps=speed, torque=torque, pulses_per_rev=ppr)
        return TraceSample(t, target, command, position, speed, torque, status, inputs,
                           self._pulse_ports(t, outputs, k33, k34),
                           int(motor.analog_input.counts(t)), analog_out,
                           int(motor.encoder.count(t)))

    def turns(self, t0: int, t1: int) -> bool:
        """Whether the position may reverse in (``t0``, ``t1``) on the trajectory of ``t0``."""
        history = self._motor.axis.history or []
        if not history:
            return False
        starts = self._piece_starts(history)
        start, profile, motion, zero, sign = history[max(bisect_right(starts, t0) - 1, 0)]
        return bool(Piece(start, profile, motion, zero, sign).turns(t0, t1))

    def _pulse_ports(self, t: int, outputs: int, k33: int, k34: int) -> int:
        """The output word at ``t`` with the rotation pulse ports (K34=7, K33 of that
        instant) filled in."""
        io = self._motor.io
        for number, signal in self._motor.pulses.signals_at(t).items():
            if io.output_function(number, k34) != OUT_ROTATION_PULSE:   # at that instant
                continue
            port = io.port_of(number, signal, k33)
            bit = 1 << (number - 1)
            outputs = (outputs | bit) if port else (outputs & ~bit)
        return outputs

    # -- what a plot labels -------------------------------------------------------------
    @property
    def input_count(self) -> int:
        """Inputs of the motor's firmware (6.6 ``?70``)."""
        return self._motor.io.input_count

    def output_functions(self) -> list[int]:
        """The function of each output now (its K34 through the firmware, ch. 3)."""
        io = self._motor.io
        return [io.output_function(n) for n in range(1, io.output_count + 1)]

    @property
    def pulses_per_rev(self) -> int:
        """Pulses per revolution now (K37)."""
        return self._motor.resolution.pulses_per_rev

    def stoppers(self, t: int | None = None) -> list[float]:
        """The machine file's stoppers (a pushed object, 4.1.4) in user pulses, in the
        user coordinates in force at ``t`` (default: now): an origin set (``|2``, an
        origin search) or K45 moves where they are counted from, not where they are."""
        motor = self._motor
        walls = motor.geometry.walls(motor.resolution.pulses_per_rev)
        zero, sign = motor.axis.zero, motor.axis.sign
        history = motor.axis.history
        if t is not None and history:
            entry = history[max(bisect_right(self._piece_starts(history), t) - 1, 0)]
            zero, sign = entry[3], entry[4]
        half = motor.axis.half_range
        return [wrap_user(sign * (raw - zero), half) for raw in walls if math.isfinite(raw)]


class TraceFeed:
    """The recording of every motor of a chain (see the module docstring).

    With ``wire`` (the device's wire faults, docs/wire-faults.md) it also counts what
    the faults did: :meth:`wire_count` at any instant, :meth:`wire_times` when;
    :attr:`wire_column` says whether a trace shows it (a fault was installed when the
    feed opened: a run without faults keeps its columns)."""

    def __init__(self, kernel: Kernel, motors: Mapping[int, Motor], observe: Observe,
                 wire: WireFaults | None = None) -> None:
        self._kernel = kernel
        self._motors = motors
        #: Kernel time the feed opened: samples are exact from here on.
        self.start = kernel.now
        self.traces: dict[int, MotorTrace] = {mid: MotorTrace(m) for mid, m in motors.items()}
        for trace in self.traces.values():
            trace._record(self.capture)
        self._remove = kernel.add_observer(self.capture)
        self._unobserve = observe(self.capture)
        self.wire_column = wire is not None and bool(wire.faults)
        self._wire_times: list[int] = []
        self._wire_counts: list[int] = []
        self._wire_total = 0
        self._unlisten_wire = wire.listen(self._wire_record) if wire is not None else None

    # -- wire faults -----------------------------------------------------------------
    def _wire_record(self, record: WireRecord) -> None:
        self._wire_total += 1
        _append(self._wire_times, self._wire_counts, record.time, self._wire_total)

    def wire_count(self, t: int) -> int:
        """How many things the wire faults did up to kernel time ``t``."""
        i = bisect_right(self._wire_times, t) - 1
        return self._wire_counts[i] if i >= 0 else 0

    def wire_times(self) -> Sequence[int]:
        """Instants a wire fault did something (ascending; read-only)."""
        return self._wire_times

    def forget_wire_before(self, upto: int) -> None:
        """Forget the wire counts only instants before ``upto`` need."""
        _trim_pairs(self._wire_times, self._wire_counts, upto)

    @property
    def now(self) -> int:
        """Kernel time now."""
        return self._kernel.now

    @property
    def motor_ids(self) -> tuple[int, ...]:
        return tuple(self.traces)

    def motor(self, motor_id: int) -> MotorTrace:
        """The recording of ``motor_id`` (``KeyError`` when it is not on the chain)."""
        return self.traces[motor_id]

    def capture(self) -> None:
        """Note the discrete state of every motor now (called after each change)."""
        for trace in self.traces.values():
            trace.capture()

    def stop(self) -> None:
        """Stop noting discrete changes (what was recorded stays readable)."""
        self._remove()
        self._unobserve()
        if self._unlisten_wire is not None:
            self._unlisten_wire()
            self._unlisten_wire = None
        for trace in self.traces.values():
            trace._unlisten(self.capture)

    def interpolated_pairs(self) -> list[tuple[int, int]]:
        """(X, Y) IDs of every pair of motors that follows an interpolation path now (4.4)."""
        pairs: list[tuple[int, int]] = []
        for motor in self._motors.values():
            path = motor.path
            if path is not None and (path.x.id, path.y.id) not in pairs:
                pairs.append((path.x.id, path.y.id))
        return sorted(pairs)


def _trim_pairs(times: list[int], values: list[Any], upto: int) -> None:
    """Drop the entries of two parallel lists before the last one at or before ``upto``."""
    i = bisect_right(times, upto) - 1
    if i > 0:
        del times[:i]
        del values[:i]


def _append(times: list[int], values: list[Any], now: int, value: object) -> None:
    """Append a change at ``now`` (a second change at the same instant replaces it)."""
    if times and times[-1] == now:
        values[-1] = value
    else:
        times.append(now)
        values.append(value)
