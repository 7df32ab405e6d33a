"""The machine-file parameters ``coolmuscle fit`` can tune, by the names a user gives.

``--params inertia,friction,kp`` names keys of the machine file (docs/machine-file.md):
``[axis.load]`` inertia, friction, torque; ``[axis.drive]`` kp (alias gain),
rotor_inertia, rated_torque, peak_torque, max_speed; ``[axis.stoppers]`` cw, ccw.  A
name alone is that key of every motor the session polls; ``inertia.2`` is motor 2's
(CML's ``.n``).  :func:`parse_params` refuses an unknown name with one line.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from ...chain.machine import BOUNDS, DRIVE_KEYS, LOAD_KEYS, MAX_POSITION, AxisSpec, Machine
from ..cli.usage import UsageError

__all__ = ["FitError", "Param", "PARAMS", "DEFAULT_PARAMS", "parse_params", "with_values"]


class FitError(UsageError):
    """A fit that cannot be done or did not succeed: one line, exit 2, nothing written."""


@dataclass(frozen=True)
class Kind:
    section: str            # load, drive, stoppers
    key: str                # the machine-file key
    unit: str
    scale: float            # a typical magnitude (the fit works in value / scale)


PARAMS: dict[str, Kind] = {
    "inertia": Kind("load", "inertia", "kg·m²", 0.45e-5),
    "friction": Kind("load", "friction", "N·m", 0.01),
    "torque": Kind("load", "torque", "N·m", 0.01),
    "kp": Kind("drive", "kp", "1/s", 300.0),
    "rotor_inertia": Kind("drive", "rotor_inertia", "kg·m²", 0.45e-5),
    "rated_torque": Kind("drive", "rated_torque", "N·m", 0.32),
    "peak_torque": Kind("drive", "peak_torque", "% rated", 300.0),
    "max_speed": Kind("drive", "max_speed", "min⁻¹", 4500.0),
    "cw": Kind("stoppers", "cw", "pulses", 1000.0),
    "ccw": Kind("stoppers", "ccw", "pulses", 1000.0),
}
ALIASES = {"gain": "kp", "load_torque": "torque", "stopper_cw": "cw", "stopper_ccw": "ccw"}
#: What ``fit`` tunes without ``--params``: the load and the position loop.
DEFAULT_PARAMS = ("inertia", "friction", "kp")


@dataclass(frozen=True)
class Param:
    """One parameter of one motor."""

    kind: Kind
    motor: int

    @property
    def name(self) -> str:
        return f"{self.kind.key}.{self.motor}"

    @property
    def bounds(self) -> tuple[float, float]:
        if self.kind.section == "stoppers":
            return -MAX_POSITION, MAX_POSITION
        return BOUNDS[self.kind.key]

    def value(self, spec: AxisSpec | None, plant_value: float) -> float | None:
        """The value ``spec`` gives (a stopper: None when the file has none)."""
        if self.kind.section == "stoppers":
            if spec is None:
                return None
            value = spec.stoppers[1 if self.kind.key == "cw" else 0]
            return value if math.isfinite(value) else None
        return plant_value


def parse_params(text: str | None, motors: int, polled: set[int]) -> list[Param]:
    """``"inertia,friction.2,gain"`` -> parameters (UsageError naming a bad name)."""
    names = [n.strip() for n in (text.split(",") if text is not None else DEFAULT_PARAMS)]
    known = ", ".join(list(PARAMS) + list(ALIASES))
    out: list[Param] = []
    for name in names:
        if not name:
            raise FitError(f"--params: an empty name in {text!r} (known: {known})")
        base, dot, motor_text = name.partition(".")
        key = ALIASES.get(base.lower(), base.lower())
        if key not in PARAMS:
            raise FitError(f"--params: unknown parameter {name!r} (known: {known}; "
                           "NAME.ID for one motor)")
        if dot:
            if not (motor_text.isdigit() and 1 <= int(motor_text) <= motors):
                raise FitError(f"--params: {name!r}: the chain has motors 1..{motors}")
            ids = [int(motor_text)]
        else:
            ids = sorted(polled) or [1]
        for motor in ids:
            param = Param(PARAMS[key], motor)
            if param in out:
                raise FitError(f"--params: {param.name} is named twice")
            out.append(param)
    if {p.kind.key for p in out} >= {"inertia", "rotor_inertia"}:
        raise FitError("--params: inertia and rotor_inertia cannot both be fitted: only "
                       "their sum acts on the shaft (docs/twin.md)")
    return out


def with_values(machine: Machine | None, params: list[Param], values: list[float]) -> Machine:
    """``machine`` with each parameter set to its value (new AxisSpec objects)."""
    axes = {a.motor: a for a in (machine.axes if machine is not None else [])}
    for param, value in zip(params, values, strict=True):
        spec = axes.get(param.motor) or AxisSpec(motor=param.motor)
        kind = param.kind
        if kind.section == "load":
            spec = dataclasses.replace(spec, load={**spec.load, LOAD_KEYS[kind.key]: value})
        elif kind.section == "drive":
            spec = dataclasses.replace(spec, motor_data={**spec.motor_data,
                                                         DRIVE_KEYS[kind.key]: value})
        else:
            lo, hi = spec.stoppers
            spec = dataclasses.replace(spec, stoppers=(lo, value) if kind.key == "cw"
                                       else (value, hi))
        axes[param.motor] = spec
    return Machine(sorted(axes.values(), key=lambda a: a.motor),
                   machine.source if machine is not None else "<fit>")
