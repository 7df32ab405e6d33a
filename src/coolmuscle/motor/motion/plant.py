"""The mechanical load the motor drives and the motor's own torque and speed ratings.

Torque Ix (cml-users-guide.txt 6.6 "?98") is in % of the rated torque, as are K47
(stopper detection) and K60 (push level); M (2.1.1 "M", 0-100 %) is a percentage of the
*maximum* motor torque, :attr:`Plant.peak_torque` % of rated (docs/fidelity.md "Servo,
load and alarms").  The load is a reflected inertia, a Coulomb friction and an optional
constant torque (a vertical axis); the machine file (docs/machine-file.md) sets them.
The defaults describe an unloaded CM2 17-size motor.

The dynamics (:mod:`coolmuscle.motor.motion.dynamics`) work in acceleration units
(pulses/s²): a torque T acts as T / (J·2π/ppr).  :meth:`Plant.drive` does that
conversion for the resolution in effect.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from .dynamics import Drive

#: Default position-loop gain (1/s): 10 000 pps -> Pe of about 33 pulses.
DEFAULT_KP = 300.0

#: CM1 is a stepper: no tracking error while the torque suffices (docs/fidelity.md).
STEPPER_KP = math.inf


@dataclass
class Plant:
    """Motor ratings and load of one axis, in SI units."""

    rotor_inertia: float = 0.45e-5      # kg·m²
    load_inertia: float = 0.0           # kg·m², reflected to the motor shaft
    coulomb_friction: float = 0.004     # N·m
    load_torque: float = 0.0            # N·m, constant; positive: held by CW torque
    rated_torque: float = 0.32          # N·m (Ix = 100)
    peak_torque: float = 300.0          # % of rated: M = 100 (2.1.1 "maximum motor torque")
    max_speed: float = 4500.0           # min⁻¹ at the nominal supply voltage
    kp: float = DEFAULT_KP              # position-loop gain, 1/s (inf: stepper)
    #: Called after any change (the motor re-solves its motion: a load changes at once).
    on_change: Callable[[], None] | None = field(default=None, repr=False, compare=False)

    def __setattr__(self, name: str, value: Any) -> None:
        object.__setattr__(self, name, value)
        listener = self.__dict__.get("on_change")
        if name != "on_change" and listener is not None:
            listener()

    @property
    def inertia(self) -> float:
        return self.rotor_inertia + self.load_inertia

    def nm_per_accel(self, ppr: int) -> float:
        """N·m it takes to accelerate the total inertia by 1 pulse/s²."""
        return self.inertia * 2.0 * math.pi / ppr

    def drive(self, ppr: int, *, limit_percent_of_rated: float, enabled: bool,
              speed_scale: float = 1.0, extra_load_nm: float = 0.0,
              walls: tuple[float, float] = (-math.inf, math.inf),
              speed_limit: float = math.inf) -> Drive:
        """The dynamics parameters for the resolution ``ppr`` (pulses per revolution).

        The loop never asks for more than the smaller of the motor's maximum speed
        (scaled by the supply) and ``speed_limit`` (min⁻¹, K40); a free shaft driven
        by its load goes no faster than the maximum speed (the back-EMF reaches the
        supply there, whatever K40 says).  A new (immutable)
        Drive at each call: the supervisor keeps the ones it made until a field of the
        plant changes (:meth:`~coolmuscle.motor.supervision.supervisor.Supervisor.drive`)."""
        per = self.nm_per_accel(ppr)
        return Drive(kp=self.kp,
                     a_limit=max(0.0, limit_percent_of_rated) / 100.0 * self.rated_torque / per,
                     a_friction=self.coulomb_friction / per,
                     a_load=(self.load_torque + extra_load_nm) / per,
                     v_max=max(0.0, min(self.max_speed * speed_scale, speed_limit)) * ppr / 60.0,
                     enabled=enabled, wall_lo=walls[0], wall_hi=walls[1],
                     percent_per_accel=100.0 * per / self.rated_torque,
                     v_free=max(0.0, self.max_speed * speed_scale) * ppr / 60.0)
