"""Driver temperature (cml-users-guide.txt 6.6 "?71 Temperature in Driver Case") from I²t.

The case temperature follows a first-order thermal model heated by the square of the
torque: at a constant torque T it settles at ``idle + rise · (T / rated)²`` with the time
constant ``time_constant``.  On each stretch of motion the heating is taken constant at
the stretch's mean of (T / rated)² (5-point Gauss–Legendre on the closed-form torque, the
exponential transient of a tracking piece on its own stretch), so the temperature rises
and cools in closed form and the instant it passes the alarm level (Ux=128) is solved,
not polled (docs/fidelity.md "Servo, load and alarms").  A free motor (``)``, an alarm)
carries no current: it only cools.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Final

from ...sim.kernel import NS_PER_S, seconds
from ..motion import expoly as xp
from ..motion.dynamics import Motion, Piece

# (not Final: compiled, a Final tuple of floats reads as unset, a mypyc 1.19 fault)
_NODES = (-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831,
          0.9061798459386640)
_WEIGHTS = (0.2369268850561891, 0.4786286704993665, 0.5688888888888889,
            0.4786286704993665, 0.2369268850561891)

#: A motion that cannot heat the case by more than this (°C) only lets it cool.
NEGLIGIBLE: Final = 0.1

#: Beyond this many time constants of the tracking loop its transient is gone.
_SETTLED: Final = 20.0


@dataclass
class Thermal:
    """The thermal state of one driver (°C, kernel ns)."""

    idle: float = 40.0            # °C at rest (6.6 "Temp.1=40")
    rise_at_rated: float = 40.0   # °C above idle at continuous rated torque
    time_constant: float = 600.0  # s
    alarm: float = 85.0           # °C: temperature alarm (Ux=128)
    temp: float = field(default=40.0)
    at_ns: int = 0

    def reset(self, temp: float | None, now: int) -> None:
        """Set the temperature now (power-up, fault injection)."""
        self.temp = self.idle if temp is None else float(temp)
        self.at_ns = int(now)

    def advance(self, motion: Motion, now: int) -> None:
        """Bring the state to ``now`` along ``motion`` (called before a re-solve)."""
        if now > self.at_ns:
            self.temp = self.temperature_at(motion, now)
            self.at_ns = now

    def temperature_at(self, motion: Motion, t_ns: int) -> float:
        """The temperature at ``t_ns`` >= the state's time."""
        if t_ns <= self.at_ns:
            return self.temp
        motion.cover_ns(t_ns)             # a motion solved in part: on to t_ns
        if self.rise_at_rated * _peak_square(motion) < NEGLIGIBLE:
            return self._after(self.temp, 0.0, (t_ns - self.at_ns) / NS_PER_S)
        temp = self.temp
        for q, dt in _stretches(motion, self.at_ns, t_ns):
            temp = self._after(temp, q, dt)
        return temp

    def first_above(self, motion: Motion, after_ns: int, limit: float) -> int | None:
        """First instant >= ``after_ns`` at which the temperature exceeds ``limit`` (on a
        motion solved in part, within the part solved: the axis asks again after it)."""
        temp = self.temperature_at(motion, after_ns)
        if temp > limit:
            return after_ns
        if self.idle + self.rise_at_rated * _peak_square(motion) <= limit:
            return None
        if not self._may_exceed(motion, after_ns, temp, limit):
            return None
        t = after_ns
        for q, dt in _stretches(motion, after_ns, None):
            steady = self.idle + self.rise_at_rated * q
            if steady > limit:
                need = self.time_constant * math.log((steady - temp) / (steady - limit))
                if need <= dt:
                    return t + max(1, math.ceil(need * NS_PER_S))
            if math.isinf(dt):
                return None
            temp = self._after(temp, q, dt)
            t += seconds(dt)
        return None

    def _may_exceed(self, motion: Motion, after_ns: int, temp: float, limit: float) -> bool:
        """Whether a bound of the temperature passes ``limit`` on ``motion`` after
        ``after_ns``: each piece heats at most as its torque bound would (the temperature
        grows with the heating and with where it starts, and on a stretch it is highest
        at an end), so ``False`` means never; a short spike at the torque limit (a csp
        step) is then answered without integrating every stretch."""
        rel = max(0.0, (after_ns - motion.origin_ns) / NS_PER_S)
        scale = _heating_scale(motion)
        for piece in motion.pieces:
            if piece.end <= rel:
                continue
            q = math.pow(piece.reach("torque") * scale, 2.0)
            if self.idle + self.rise_at_rated * q > temp:
                temp = self._after(temp, q, piece.end - max(rel, piece.start))
                if temp > limit:
                    return True
        return False

    def _after(self, temp: float, q: float, dt: float) -> float:
        steady = self.idle + self.rise_at_rated * q
        if math.isinf(dt):
            return steady
        return steady + (temp - steady) * math.exp(-dt / self.time_constant)


def _heating_scale(motion: Motion) -> float:
    """Torque (pulses/s²) to a fraction of rated, for heating: 0 with the servo off
    (the driver sends no current into a free motor, whatever its pieces say)."""
    drive = motion.drive
    return drive.percent_per_accel / 100.0 if drive.enabled else 0.0


def _peak_square(motion: Motion) -> float:
    """A bound of (torque / rated)² over the whole motion."""
    return math.pow(motion.peak("torque") * _heating_scale(motion), 2.0)


def _stretches(motion: Motion, t0: int, t1: int | None) -> Iterator[tuple[float, float]]:
    """(mean (T/rated)², duration s) of each stretch of ``motion`` within [t0, t1]."""
    a_rel = max(0.0, (t0 - motion.origin_ns) / NS_PER_S)
    b_rel = math.inf if t1 is None else (t1 - motion.origin_ns) / NS_PER_S
    scale = _heating_scale(motion)
    for piece in motion.pieces:
        lo, hi = max(a_rel, piece.start), min(b_rel, piece.end)
        if hi <= lo:
            continue
        a, b = lo - piece.start, hi - piece.start
        cuts = [a, b]
        if piece.k > 0.0 and a < _SETTLED / piece.k < b:
            cuts = [a, _SETTLED / piece.k, b]
        for x, y in zip(cuts, cuts[1:]):
            yield _mean_square(piece, x, y) * scale * scale, y - x


def _mean_square(piece: Piece, a: float, b: float) -> float:
    """Mean of torque² over [a, b] (at ``a`` when the stretch is endless)."""
    if math.isinf(b):
        return math.pow(xp.value(piece.torque, piece.k, a), 2.0)
    half, mid = (b - a) / 2.0, (a + b) / 2.0
    total = 0.0
    for node, weight in zip(_NODES, _WEIGHTS):
        total += weight * math.pow(xp.value(piece.torque, piece.k, mid + half * node), 2.0)
    return total / 2.0
