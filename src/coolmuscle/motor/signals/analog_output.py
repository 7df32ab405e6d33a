"""Analog output (cml-users-guide.txt ch. 3 K35; Modbus K78+54 "Analog Output", 5.6.7).

The output is 2.5 V ± 1.67 V for ± the full scale of the K35 type; beyond the full
scale "it will be replicated": the value wraps around (a saw tooth, like a position
seen through a window of ±1024 pulses).  Types (ch. 3 K35 table):

====  ==================================  ==================
K35   quantity                            ± full scale
====  ==================================  ==================
0/1   target position (x8)                1024 / 128 pulses
2/3   current position (x8)               1024 / 128 pulses
4/5   position error (x8)                 1024 / 128 pulses
6/7   current speed (x8)                  2400 / 300 min⁻¹
8/9   current torque (x8)                 100 / 12.5 %
====  ==================================  ==================

Readings: :func:`output_volts` (trace column ``analog_out``, volts) and
:func:`volts_to_register` (the Modbus register: the same 10-bit scale as the analog
input, 0..1023 for 0..5 V, so 2.5 V reads 512).  docs/fidelity.md "Analog".
"""

from __future__ import annotations

import math

from .analog import MAX_COUNT, volts_to_counts

CENTER_V = 2.5
SWING_V = 1.67
_FULL_SCALE = {0: 1024.0, 2: 1024.0, 4: 1024.0, 6: 2400.0, 8: 100.0}


def wrap(z: float) -> float:
    """Fold z into [-1, 1): the output repeats beyond its range (K35)."""
    if not math.isfinite(z):
        return 0.0
    return ((z + 1.0) % 2.0) - 1.0


def output_volts(k35: int, *, target: float, position: float, error: float,
                 speed_pps: float, torque: float, pulses_per_rev: int) -> float:
    """The analog output voltage for K35 = ``k35`` and the motor's values."""
    kind = k35 - k35 % 2
    values = {0: target, 2: position, 4: error,
              6: speed_pps * 60.0 / pulses_per_rev, 8: torque}
    value = values.get(kind)
    if value is None:
        return CENTER_V
    full = _FULL_SCALE[kind] / (8.0 if k35 % 2 else 1.0)
    return CENTER_V + SWING_V * wrap(value / full)


def volts_to_register(volts: float) -> int:
    """Volts as the Modbus "Analog Output" value: 10-bit, 0..1023 for 0..5 V."""
    return max(0, min(MAX_COUNT, round(volts_to_counts(volts))))
