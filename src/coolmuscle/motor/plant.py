"""The mechanical load the motor drives: inertia, friction, and the torque it takes.

Torque Ix (cml-users-guide.txt 6.6 "?98", % of rated torque) is what it takes to
accelerate the rotor and load inertia against viscous and Coulomb friction.  The
machine file (docs/machine-file.md) sets these numbers; the defaults describe an
unloaded CM2 17-size motor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .servo import DEFAULT_KP


@dataclass
class Plant:
    """Load model of one axis, in SI units."""

    rotor_inertia: float = 0.45e-5      # kg·m²
    load_inertia: float = 0.0           # kg·m², reflected to the motor shaft
    coulomb_friction: float = 0.004     # N·m
    viscous_friction: float = 2.0e-5    # N·m per rad/s
    rated_torque: float = 0.32          # N·m (100 %)
    kp: float = DEFAULT_KP              # position-loop gain, 1/s

    @property
    def inertia(self) -> float:
        return self.rotor_inertia + self.load_inertia

    def torque_nm(self, accel_pps2: float, speed_pps: float, ppr: int) -> float:
        """Torque needed to move at this acceleration and speed."""
        to_rad = 2 * math.pi / ppr
        omega = speed_pps * to_rad
        friction = 0.0
        if abs(speed_pps) > 1e-9:
            friction = math.copysign(self.coulomb_friction, speed_pps) + self.viscous_friction * omega
        return self.inertia * accel_pps2 * to_rad + friction

    def torque_percent(self, accel_pps2: float, speed_pps: float, ppr: int) -> float:
        """Ix, % of rated torque."""
        return 100.0 * self.torque_nm(accel_pps2, speed_pps, ppr) / self.rated_torque
