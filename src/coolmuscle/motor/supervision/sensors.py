"""The machine around one axis, as the motor sees it: stoppers, position sensors, Z phase.

Positions here are machine positions (the axis's raw pulses, docs/machine-file.md),
written in pulses at the machine file's ``ppr`` and scaled to the resolution in effect
(ch. 3 K37) whenever they are used.  A :class:`PositionSensor` drives a motor input: it
is a :class:`~coolmuscle.motor.motion.axis.Watcher` that asks the shaft motion for the instant
the *actual* position enters or leaves its range, so the input changes exactly then
(and is re-solved on every re-plan).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

from ..motion import expoly as xp
from ..motion.axis import Watcher

#: An edge counts as crossed this far past it (pulses): no chatter from float noise.
EDGE_MARGIN: Final = 1e-6

if TYPE_CHECKING:
    from ..core import MotorCore
    from ..motion.axis import Axis


@dataclass
class PositionSensor(Watcher):
    """A switch that is on while the shaft is within [lo, hi] (machine pulses at ``ppr``)."""

    name: str
    input: int
    lo: float
    hi: float
    ppr: int = 1000
    normally_closed: bool = False
    motor: MotorCore | None = field(default=None, repr=False)
    inside: bool = False

    def _range(self, motor: MotorCore) -> tuple[float, float]:
        scale = motor.resolution.pulses_per_rev / self.ppr
        return self.lo * scale, self.hi * scale

    def level(self) -> bool:
        """The electrical level it drives (a normally closed switch opens inside)."""
        return self.inside != self.normally_closed

    def attach(self, motor: MotorCore) -> None:
        """Start driving ``motor``'s input from the shaft position."""
        self.motor = motor
        lo, hi = self._range(motor)
        self.inside = lo <= motor.axis.raw_actual() <= hi
        motor.set_input_level(self.input, self.level())
        motor.axis.add_watcher(self)

    def next_time(self, axis: Axis, after_ns: int) -> int | None:
        if self.motor is None:
            return None
        lo, hi = self._range(self.motor)
        motion = axis.motion

        def far(p):  # type: ignore[no-untyped-def]
            low, high = motion.span(p)
            return (high < lo or low > hi) if not self.inside else (lo < low and high < hi)
        if self.inside:
            alts = []
            if math.isfinite(hi):
                alts.append(lambda p: [xp.plus(p.pos, -hi - EDGE_MARGIN)])
            if math.isfinite(lo):
                alts.append(lambda p: [xp.plus(xp.scale(p.pos, -1.0), lo - EDGE_MARGIN)])
            return motion.first(after_ns, *alts, skip=far) if alts else None

        def enter(p):  # type: ignore[no-untyped-def]
            conds = []
            if math.isfinite(lo):
                conds.append(xp.plus(p.pos, -lo - EDGE_MARGIN))
            if math.isfinite(hi):
                conds.append(xp.plus(xp.scale(p.pos, -1.0), hi - EDGE_MARGIN))
            return conds
        return motion.first(after_ns, enter, skip=far)

    def fire(self, axis: Axis) -> None:
        del axis
        self.inside = not self.inside
        if self.motor is not None:
            self.motor.set_input_level(self.input, self.level())


@dataclass
class Geometry:
    """Stoppers, sensors and the Z phase of one axis (machine pulses at ``ppr``)."""

    ppr: int = 1000
    stopper_ccw: float = -math.inf
    stopper_cw: float = math.inf
    z_phase: float = 0.0
    sensors: list[PositionSensor] = field(default_factory=list)

    def walls(self, ppr: int) -> tuple[float, float]:
        """The hard stoppers in raw pulses at resolution ``ppr``."""
        scale = ppr / self.ppr
        return self.stopper_ccw * scale, self.stopper_cw * scale

    def z_raw(self, ppr: int) -> float:
        return self.z_phase * ppr / self.ppr
