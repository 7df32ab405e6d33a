"""Rotation pulse output (cml-users-guide.txt 5.2; ch. 3 K24, K33, K34=7).

An output whose K34 digit is 7 is ON in the first half of every K24 pulses of the
current position and OFF in the second half; when outputs 1 and 2 are both 7 they
are a quadrature pair (A on output 1, B on output 2, 90° apart; K34 "77" for
short).  Each switch happens 1/5000 of a revolution past its boundary in
the direction of motion (5.2 "±1/5000ppr hysteresis"), so the switching points
differ between CW and CCW.

The signal is a function of the actual position and its history, evaluated when it
is read (?50, Modbus, trace): a :class:`~coolmuscle.motor.motion.trajectory.Track` with
quarter-period steps keeps the state, and edge times are solved, never sampled.
The pulses raise no kernel events and no K23 output reports (those cover the
general-use outputs only).  Choices: docs/fidelity.md "Rotation pulses".
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..motion.trajectory import Schmitt, Timeline, Track
from ..state.output_functions import OUT_ROTATION_PULSE

if TYPE_CHECKING:
    from ..core import MotorCore

#: Hysteresis: 1/5000 of a revolution (5.2), in pulses of the K37 resolution.
HYSTERESIS_PER_REV = 1 / 5000


def _phase_a(quarter: int) -> bool:
    """A is ON in quarters 0 and 1 of each period: the first half (5.2)."""
    return quarter % 4 in (0, 1)


def _phase_b(quarter: int) -> bool:
    """B lags A by a quarter period: ON in quarters 1 and 2."""
    return quarter % 4 in (1, 2)


class RotationPulses:
    """The K34=7 outputs of one motor."""

    def __init__(self, motor: MotorCore, timeline: Timeline) -> None:
        self.motor = motor
        self.timeline = timeline
        self.track: Track | None = None
        self._config: tuple[int, int, int, int] | None = None
        motor.params.on_change(self._param_changed)
        self.refresh()

    # -- configuration --------------------------------------------------------
    def outputs(self) -> list[int]:
        """Output numbers whose K34 function is the rotation pulse (digit 7)."""
        io = self.motor.io
        return [n for n in range(1, io.output_count + 1)
                if io.output_function(n) == OUT_ROTATION_PULSE]

    def quadrature(self) -> bool:
        """Outputs 1 and 2 both 7: quadrature encoder output (ch. 3 K34, K24)."""
        found = self.outputs()
        return 1 in found and 2 in found

    def hysteresis(self) -> float:
        """±1/5000 revolution in pulses (5.2: ±10 pulses at 50000 ppr)."""
        return self.motor.resolution.pulses_per_rev * HYSTERESIS_PER_REV

    def offset(self) -> int:
        """CM1 K54 "Quadrature output offset" (pulses): the pattern starts there."""
        return self.motor.k(54) if self.motor.firmware.name == "cm1" else 0

    def refresh(self) -> None:
        """Start, restart or stop following the position after K24/K34/K37 changes."""
        config = (self.motor.k(24), self.motor.k(34), self.motor.k(37), self.offset())
        active = bool(self.outputs())
        if active and config == self._config and self.track is not None:
            return
        if self.track is not None:
            self.track.close()
            self.track = None
        self._config = config if active else None
        if active:
            h = self.hysteresis()
            self.track = Track(self.timeline, Schmitt(self.motor.k(24) / 4.0, h, h),
                               offset=-float(self.offset()))

    def _param_changed(self, k: int, old: int, new: int) -> None:
        del old, new
        if k in (24, 34, 37, 54):
            self.refresh()

    # -- signals ----------------------------------------------------------------
    def _signal_of(self, number: int, quarter: int) -> bool:
        if number == 2 and self.quadrature():
            return _phase_b(quarter)
        return _phase_a(quarter)

    def signal(self, number: int) -> bool:
        """The output *signal* now (before K33 logic)."""
        if self.track is None:
            return False
        return self._signal_of(number, self.track.state())

    def signals_at(self, t: int) -> dict[int, bool]:
        """Signal of each rotation pulse output at kernel time ``t`` (trace)."""
        if self.track is None:
            return {}
        quarter = self.track.state_at(t)
        return {n: self._signal_of(n, quarter) for n in self.outputs()}

    def edge_times(self, t0: int, t1: int) -> list[int]:
        """Every instant in (t0, t1] where a pulse output switches (exact plots)."""
        if self.track is None:
            return []
        quad = self.quadrature()
        times = []
        previous = self.track.state_at(t0)
        for t, quarter in self.track.edges(t0, t1):
            if quad or _phase_a(quarter) != _phase_a(previous):
                times.append(t)
            previous = quarter
        return times
