"""Closed-form servo tracking: the actual position follows the command with an error Pe.

CM2 is a servo (cml-users-guide.txt 1.1; 6.6 "?95 Position error").  The position
loop is modelled as first order, ``e' = v_cmd(t) - kp * e`` with ``e = cmd - actual``,
so the error of a moving motor is about ``v / kp`` and decays as ``exp(-kp t)`` once
the command stops.  On each profile segment the command speed is a polynomial of
degree <= 2 (``v + a t + j t²/2``), so ``e`` is a polynomial plus one exponential:
exact at any instant, no time steps.  The actual speed is ``kp * e``.

The load model (inertia, friction, contact, torque limit) in
:mod:`coolmuscle.motor.plant` uses the same solution.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from typing import Callable

from .profile import Profile
from ..sim.kernel import NS_PER_S

#: Default position-loop gain (1/s): 10 000 pps -> Pe of about 33 pulses.
DEFAULT_KP = 300.0


@dataclass(frozen=True, slots=True)
class _Piece:
    """Error solution on one segment: e(τ) = c0 + c1 τ + c2 τ² + d exp(-kp τ)."""

    start: float
    duration: float
    c0: float
    c1: float
    c2: float
    d: float

    def error(self, tau: float, kp: float) -> float:
        return self.c0 + self.c1 * tau + self.c2 * tau * tau + self.d * math.exp(-kp * tau)

    def error_rate(self, tau: float, kp: float) -> float:
        return self.c1 + 2.0 * self.c2 * tau - kp * self.d * math.exp(-kp * tau)


def _piece(start: float, duration: float, v: float, a: float, j: float, e0: float,
           kp: float) -> _Piece:
    c2 = j / (2.0 * kp)
    c1 = (a - 2.0 * c2) / kp
    c0 = (v - c1) / kp
    return _Piece(start, duration, c0, c1, c2, e0 - c0)


class Tracking:
    """The tracking error of one commanded profile, starting from error ``e0``."""

    def __init__(self, profile: Profile, e0: float = 0.0, kp: float = DEFAULT_KP) -> None:
        self.profile = profile
        self.kp = kp
        self.e0 = e0
        self._pieces: list[_Piece] = []
        self._starts: list[float] = []
        e = e0
        for seg in profile.segments:
            piece = _piece(seg.start, seg.duration, seg.v, seg.a, seg.j, e, kp)
            self._pieces.append(piece)
            self._starts.append(seg.start)
            if math.isinf(seg.duration):
                break
            e = piece.error(seg.duration, kp)
        last = self._pieces[-1] if self._pieces else None
        self._end = last.start + last.duration if last else 0.0
        self._e_end = e

    def _rel(self, t_ns: int) -> float:
        return (t_ns - self.profile.origin_ns) / NS_PER_S

    def error_at(self, t_ns: int) -> float:
        """Pe (pulses, command minus actual) at kernel time ``t_ns``."""
        t = self._rel(t_ns)
        if t <= 0.0:
            return self.e0
        if t >= self._end:
            return self._e_end * math.exp(-self.kp * (t - self._end))
        i = bisect_right(self._starts, t) - 1
        piece = self._pieces[i]
        return piece.error(t - piece.start, self.kp)

    def actual_velocity_at(self, t_ns: int) -> float:
        """Actual speed (pulses/s) = kp * e."""
        return self.kp * self.error_at(t_ns)

    def settle_ns(self, window: float) -> int:
        """Time after the command ends until |Pe| <= ``window`` (0 if already)."""
        e = abs(self._e_end)
        if e <= window or window <= 0:
            return 0
        return int(math.ceil(math.log(e / window) / self.kp * NS_PER_S))

    @property
    def error_at_end(self) -> float:
        """Pe when the command stops (the settling starts from here)."""
        return self._e_end

    # -- where the actual motion reverses (rotation pulses, external encoder) --
    def velocity_zeros(self, t0_ns: int, t1_ns: int) -> list[int]:
        """Kernel instants in (``t0_ns``, ``t1_ns``) where the actual speed changes sign.

        Between two of them the actual position is monotonic, so positions reached
        and band exits can be solved there (:mod:`coolmuscle.motor.trajectory`).
        On a segment e(τ) = c0 + c1 τ + c2 τ² + d exp(-kp τ): e'' is monotonic, so
        e' has at most two zeros and e at most three; each is bracketed and bisected.
        After the command ends the error only decays, so there are none.
        """
        origin = self.profile.origin_ns
        lo, hi = self._rel(t0_ns), self._rel(t1_ns)
        found: list[int] = []
        for piece in self._pieces:
            a, b = max(lo, piece.start), min(hi, piece.start + piece.duration)
            if a >= b:
                continue
            for tau in _error_zeros(piece, self.kp, a - piece.start, b - piece.start):
                t_ns = origin + round((piece.start + tau) * NS_PER_S)
                if t0_ns < t_ns < t1_ns:
                    found.append(t_ns)
        return sorted(set(found))


def _error_zeros(piece: _Piece, kp: float, lo: float, hi: float) -> list[float]:
    """Sign changes of the piece's error in [lo, hi] (local seconds)."""
    cuts = [lo, hi]
    if piece.d != 0.0 and piece.c2 != 0.0:
        ratio = -2.0 * piece.c2 / (kp * kp * piece.d)
        if ratio > 0.0:
            tau2 = -math.log(ratio) / kp
            if lo < tau2 < hi:
                cuts = [lo, tau2, hi]
    slope_cuts = [cuts[0]]
    for a, b in zip(cuts, cuts[1:]):
        root = _bisect_sign(lambda t: piece.error_rate(t, kp), a, b)
        if root is not None:
            slope_cuts.append(root)
        slope_cuts.append(b)
    zeros = []
    for a, b in zip(slope_cuts, slope_cuts[1:]):
        root = _bisect_sign(lambda t: piece.error(t, kp), a, b)
        if root is not None and lo < root < hi:
            zeros.append(root)
    return zeros


def _bisect_sign(f: Callable[[float], float], a: float, b: float) -> float | None:
    """A root of ``f`` in (a, b) when f(a) and f(b) have strictly opposite signs."""
    fa, fb = f(a), f(b)
    if fa == 0.0 or fb == 0.0 or (fa < 0.0) == (fb < 0.0):
        return None
    for _ in range(200):
        mid = 0.5 * (a + b)
        if mid <= a or mid >= b:
            break
        fm = f(mid)
        if fm == 0.0:
            return mid
        if (fm < 0.0) == (fa < 0.0):
            a, fa = mid, fm
        else:
            b = mid
    return 0.5 * (a + b)
