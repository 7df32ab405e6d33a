"""Closed-form functions of time: a polynomial plus one decaying exponential, and roots.

Every quantity of the servo and load model (:mod:`coolmuscle.motor.motion.dynamics`) is, on one
piece of motion, ``f(τ) = c0 + c1 τ + ... + cn τⁿ + d·exp(-k τ)``: the command is a
cubic (piecewise-constant jerk, :mod:`.profile`), the first-order tracking error adds one
exponential, saturated and free motion are quadratics, a braking curve squares a speed.
This module owns that form (``F``, a tuple ending with ``d``, with the rate ``k`` passed
alongside) and the instants where such a function changes sign, found by a derivative
cascade: the n-th derivative of ``f`` is ``n! cn + d (-k)ⁿ e^(-kτ)``, monotonic, so it
has at most one root, which bounds the monotonic stretches of every lower derivative;
each root is then bracketed and refined (safeguarded Newton).  Nothing is sampled on a
time grid (docs/architecture.md rule 2).
"""

from __future__ import annotations

import math
from typing import Iterable, Sequence

#: (c0, c1, ..., cn, d): c0 + c1 τ + ... + cn τⁿ + d·exp(-k τ); n >= 3 by convention.
F = tuple[float, ...]

ZERO: F = (0.0, 0.0, 0.0, 0.0, 0.0)
INF = math.inf
_ITERATIONS = 100


def const(c: float) -> F:
    return (float(c), 0.0, 0.0, 0.0, 0.0)


def value(f: F, k: float, t: float) -> float:
    """``f(t)``."""
    if len(f) == 5:
        c0, c1, c2, c3, d = f
        out = c0 + t * (c1 + t * (c2 + t * c3))
        return out + d * math.exp(-k * t) if d else out
    out = 0.0
    for c in reversed(f[:-1]):
        out = out * t + c
    d = f[-1]
    if d:
        out += d * math.exp(-k * t)
    return out


def deriv(f: F, k: float) -> F:
    """``f'``."""
    if len(f) == 5:
        return (f[1], 2.0 * f[2], 3.0 * f[3], 0.0, -k * f[4])
    poly = tuple(i * c for i, c in enumerate(f[:-1]) if i) + (0.0,)
    return _pad(poly) + (-k * f[-1],)


def _pad(poly: tuple[float, ...]) -> tuple[float, ...]:
    return poly + (0.0,) * (4 - len(poly)) if len(poly) < 4 else poly


def _poly(f: F, n: int) -> tuple[float, ...]:
    return f[:-1] + (0.0,) * (n - len(f) + 1)


def add(f: F, g: F) -> F:
    if len(f) == 5 and len(g) == 5:
        return (f[0] + g[0], f[1] + g[1], f[2] + g[2], f[3] + g[3], f[4] + g[4])
    n = max(len(f), len(g)) - 1
    return tuple(a + b for a, b in zip(_poly(f, n), _poly(g, n))) + (f[-1] + g[-1],)


def sub(f: F, g: F) -> F:
    if len(f) == 5 and len(g) == 5:
        return (f[0] - g[0], f[1] - g[1], f[2] - g[2], f[3] - g[3], f[4] - g[4])
    return add(f, scale(g, -1.0))


def plus(f: F, c: float) -> F:
    """``f + c``."""
    return (f[0] + c,) + f[1:]


def scale(f: F, s: float) -> F:
    if len(f) == 5:
        return (f[0] * s, f[1] * s, f[2] * s, f[3] * s, f[4] * s)
    return tuple(c * s for c in f)


def spread(f: F, b: float) -> float:
    """A bound of ``|f(τ) - c0|`` on [0, b] (∞ when b is and ``f`` has a τ term)."""
    out = abs(f[-1])
    for i in range(1, len(f) - 1):
        c = f[i]
        if c:
            if math.isinf(b):
                return INF
            out += abs(c) * b ** i
    return out


def abs_bound(f: F, b: float) -> float:
    """A bound of ``|f|`` on [0, b] (∞ when b is and ``f`` has a τ term): |c0| plus
    :func:`spread`, written out for the 5-tuple every motion piece is."""
    out = abs(f[0]) + abs(f[-1])
    if len(f) == 5:
        c1, c2, c3 = f[1], f[2], f[3]
        if c1 or c2 or c3:
            if math.isinf(b):
                return INF
            if c1:
                out += abs(c1) * b ** 1
            if c2:
                out += abs(c2) * b ** 2
            if c3:
                out += abs(c3) * b ** 3
        return out
    return abs(f[0]) + spread(f, b)


def mul(f: F, g: F) -> F:
    """Product of two polynomials (no exponential part).  Zero coefficients above the
    cubic are dropped: a product of degree 3 or less is the 5-tuple every piece uses
    (the braking curve of a standing command: its roots on the 5-tuple path, the same
    numbers, tests/test_expoly.py)."""
    if f[-1] or g[-1]:
        raise ValueError("mul() takes polynomials only")
    out = [0.0] * (len(f) + len(g) - 3)
    for i, a in enumerate(f[:-1]):
        if a:
            for j, b in enumerate(g[:-1]):
                out[i + j] += a * b
    while len(out) > 4 and out[-1] == 0.0:
        out.pop()
    return _pad(tuple(out)) + (0.0,)


def shift(f: F, k: float, a: float) -> F:
    """The same function with its origin moved to ``a``: ``g(τ) = f(a + τ)``."""
    if not a:
        return f
    if len(f) == 5:
        c0, c1, c2, c3, d = f
        return (c0 + a * (c1 + a * (c2 + a * c3)), c1 + a * (2.0 * c2 + 3.0 * c3 * a),
                c2 + 3.0 * c3 * a, c3, d * math.exp(-k * a) if d else 0.0)
    poly = f[:-1]
    n = len(poly)
    out = []
    for j in range(n):
        acc, binom = 0.0, 1.0
        for i in range(j, n):
            if i > j:
                binom = binom * i / (i - j)
            acc += poly[i] * binom * a ** (i - j)
        out.append(acc)
    d = f[-1]
    return tuple(out) + (d * math.exp(-k * a) if d else 0.0,)


def _degree(f: F) -> int:
    if len(f) == 5:
        return (3 if f[3] != 0.0 else 2 if f[2] != 0.0 else 1 if f[1] != 0.0
                else 0 if f[0] != 0.0 else -1)
    for i in range(len(f) - 2, -1, -1):
        if f[i] != 0.0:
            return i
    return -1


def upper_bound(f: F, k: float, a: float, b: float) -> float:
    """A cheap upper bound of ``f`` on [a, b] (used to skip root searches)."""
    g = shift(f, k, a) if a else f
    w = b - a
    out = g[0]
    if len(g) == 5:
        g1, g2, g3, gd = g[1], g[2], g[3], g[4]
        if g1 > 0.0 or g2 > 0.0 or g3 > 0.0:
            if math.isinf(w):
                return INF
            if g1 > 0.0:
                out += g1 * w ** 1
            if g2 > 0.0:
                out += g2 * w ** 2
            if g3 > 0.0:
                out += g3 * w ** 3
        if gd > 0.0:
            out += gd
        return out
    for i in range(1, len(g) - 1):
        if g[i] > 0.0:
            if math.isinf(w):
                return INF
            out += g[i] * w ** i
    if g[-1] > 0.0:
        out += g[-1]
    return out


def _sign(x: float) -> int:
    return (x > 0.0) - (x < 0.0)


def _limit_sign(f: F) -> int:
    """Sign of ``f`` as τ -> ∞ (k > 0 makes the exponential vanish)."""
    deg = _degree(f)
    if deg >= 0:
        return _sign(f[deg])
    return _sign(f[-1])


def _refine(f: F, k: float, lo: float, hi: float, flo: float) -> float:
    """The root of ``f`` in [lo, hi] where ``f`` is monotonic and changes sign."""
    if len(f) != 5:
        return _refine_any(f, k, lo, hi, flo)
    # value(f) and value(f') written out (the same expressions, no calls): hot path
    c0, c1, c2, c3, d = f
    s1, s2, s3, sd = f[1], 2.0 * c2, 3.0 * c3, -k * d      # deriv(f, k)
    exp = math.exp
    t = 0.5 * (lo + hi)
    for _ in range(_ITERATIONS):
        ft = c0 + t * (c1 + t * (c2 + t * c3))
        if d:
            ft = ft + d * exp(-k * t)
        if ft == 0.0:
            return t
        if (ft < 0.0) == (flo < 0.0):
            lo, flo = t, ft
        else:
            hi = t
        if hi - lo <= 1e-15 * max(1.0, abs(hi)):
            break
        slope = s1 + t * (s2 + t * (s3 + t * 0.0))
        if sd:
            slope = slope + sd * exp(-k * t)
        step = t - ft / slope if slope != 0.0 else lo - 1.0
        t = step if lo < step < hi else 0.5 * (lo + hi)
    return 0.5 * (lo + hi)


def _refine_any(f: F, k: float, lo: float, hi: float, flo: float) -> float:
    """:func:`_refine` for any degree."""
    df = deriv(f, k)
    t = 0.5 * (lo + hi)
    for _ in range(_ITERATIONS):
        ft = value(f, k, t)
        if ft == 0.0:
            return t
        if (ft < 0.0) == (flo < 0.0):
            lo, flo = t, ft
        else:
            hi = t
        if hi - lo <= 1e-15 * max(1.0, abs(hi)):
            break
        slope = value(df, k, t)
        step = t - ft / slope if slope != 0.0 else lo - 1.0
        t = step if lo < step < hi else 0.5 * (lo + hi)
    return 0.5 * (lo + hi)


def _bracket_end(f: F, k: float, lo: float, want: int) -> float:
    """A finite ``hi`` > lo with sign(f(hi)) == want, on a monotonic tail."""
    step = max(1.0, abs(lo))
    hi = lo + step
    for _ in range(2000):
        if _sign(value(f, k, hi)) == want:
            return hi
        step *= 2.0
        hi = lo + step
        if math.isinf(hi):
            break
    return INF


def _critical(f: F, k: float, a: float, b: float) -> list[float]:
    """Instants in (a, b) where ``f'`` changes sign."""
    df = deriv(f, k)
    if df[-1] == 0.0 or k == 0.0:
        deg = _degree(df)
        if deg <= 0:
            return []
        if deg == 1:
            r = -df[0] / df[1]
            return [r] if a < r < b else []
        if deg == 2:
            return [r for r in _quadratic(df[2], df[1], df[0]) if a < r < b]
    return roots(df, k, a, b)


def _quadratic(c2: float, c1: float, c0: float) -> list[float]:
    """Real roots of c2 x² + c1 x + c0 where the sign changes, ascending."""
    if c2 == 0.0:
        return [] if c1 == 0.0 else [-c0 / c1]
    disc = c1 * c1 - 4.0 * c2 * c0
    if disc <= 0.0:
        return []
    q = -0.5 * (c1 + math.copysign(math.sqrt(disc), c1))
    found = [q / c2] if q == 0.0 else [q / c2, c0 / q]
    return sorted(found)


def _fold(f: F, k: float) -> F:
    """With k == 0 the exponential is the constant d."""
    if k == 0.0 and f[-1]:
        return (f[0] + f[-1],) + f[1:-1] + (0.0,)
    return f


def roots(f: F, k: float, a: float, b: float) -> list[float]:
    """Instants in (a, b) where ``f`` changes sign, ascending (``b`` may be ∞)."""
    if b <= a:
        return []
    if k == 0.0:
        f = _fold(f, k)
    if len(f) == 5:
        return _roots5(f[0], f[1], f[2], f[3], f[4], k, a, b)
    deg, d = _degree(f), f[-1]
    if deg <= 0:
        if d == 0.0:
            return []
        # c0 + d e^{-kτ}: monotonic; at most one root
        if f[0] == 0.0 or (-f[0] / d) <= 0.0:
            return []
        r = -math.log(-f[0] / d) / k
        return [r] if a < r < b else []
    return _roots_between(f, k, [a, *_critical(f, k, a, b), b])


def _roots5(c0: float, c1: float, c2: float, c3: float, d: float, k: float,
            a: float, b: float) -> list[float]:
    """:func:`roots` of the 5-tuple (c0, c1, c2, c3, d) on (a, b), b > a, already folded.

    The hot path of the dynamics: the same derivative cascade and the same arithmetic
    as the general code (:func:`_critical`, :func:`value`), on scalars."""
    deg = 3 if c3 != 0.0 else 2 if c2 != 0.0 else 1 if c1 != 0.0 else 0 if c0 != 0.0 else -1
    if deg <= 0:
        if d == 0.0:
            return []
        # c0 + d e^{-kτ}: monotonic; at most one root
        if c0 == 0.0 or (-c0 / d) <= 0.0:
            return []
        r = -math.log(-c0 / d) / k
        return [r] if a < r < b else []
    # critical points: where f' = (c1, 2 c2, 3 c3, 0, -k d) changes sign
    s0, s1, s2, sd = c1, 2.0 * c2, 3.0 * c3, -k * d
    if sd == 0.0 or k == 0.0:
        if s2 != 0.0:
            critical = [r for r in _quadratic(s2, s1, s0) if a < r < b]
        elif s1 != 0.0:
            r = -s0 / s1
            critical = [r] if a < r < b else []
        else:
            critical = []
    else:
        critical = _roots5(s0, s1, s2, 0.0, sd, k, a, b)
    if not critical and not math.isinf(b):
        # one monotonic stretch (the usual case): f at both ends
        exp = math.exp
        flo = c0 + a * (c1 + a * (c2 + a * c3))
        fhi = c0 + b * (c1 + b * (c2 + b * c3))
        if d:
            flo = flo + d * exp(-k * a)
            fhi = fhi + d * exp(-k * b)
        if flo == 0.0 or fhi == 0.0 or (flo < 0.0) == (fhi < 0.0):
            return []
        return [_refine((c0, c1, c2, c3, d), k, a, b, flo)]
    return _roots_between((c0, c1, c2, c3, d), k, [a, *critical, b])


def _roots_between(f: F, k: float, cuts: list[float]) -> list[float]:
    """Sign changes of ``f`` on each stretch between consecutive ``cuts`` (on which it
    is monotonic); the last cut may be ∞."""
    found: list[float] = []
    fnext: float | None = None      # f at the previous stretch's (finite) end
    for i in range(len(cuts) - 1):
        lo, hi = cuts[i], cuts[i + 1]
        flo = value(f, k, lo) if fnext is None else fnext
        fnext = None
        if math.isinf(hi):
            want = _limit_sign(f)
            if want == 0 or want == _sign(flo) or flo == 0.0:
                continue
            hi = _bracket_end(f, k, lo, want)
            if math.isinf(hi):
                continue
            fhi = value(f, k, hi)
        else:
            fhi = fnext = value(f, k, hi)
        if flo == 0.0 or fhi == 0.0 or (flo < 0.0) == (fhi < 0.0):
            continue
        found.append(_refine(f, k, lo, hi, flo))
    return found


def first_true(conds: Sequence[F], k: float, a: float, b: float) -> float | None:
    """First τ in [a, b) at which every ``cond(τ) > 0``; ``None`` if never.

    The interval is cut at every sign change of every condition; the first stretch
    whose midpoint satisfies all of them starts at the answer.  Conditions whose
    cheap upper bound is <= 0 make the answer ``None`` at once.
    """
    if b <= a:
        return None
    for cond in conds:
        if upper_bound(cond, k, a, b) <= 0.0:
            return None
    found = _all_roots(conds, k, a, b)
    cuts = sorted({a, *found}) if found else [a]
    last = len(cuts) - 1
    for i, lo in enumerate(cuts):
        hi = cuts[i + 1] if i < last else b
        mid = lo + 1.0 if math.isinf(hi) else 0.5 * (lo + hi)
        for c in conds:
            if not value(c, k, mid) > 0.0:
                break
        else:
            return lo
    return None


def _all_roots(conds: Iterable[F], k: float, a: float, b: float) -> list[float]:
    out: list[float] = []
    for cond in conds:
        out.extend(roots(cond, k, a, b))
    return out
