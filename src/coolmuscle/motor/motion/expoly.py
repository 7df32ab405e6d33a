"""Closed-form functions of time: a polynomial plus one decaying exponential, and roots.

Every quantity of the servo and load model (:mod:`coolmuscle.motor.motion.dynamics`) is, on one
piece of motion, ``f(τ) = c0 + c1 τ + ... + cn τⁿ + d·exp(-k τ)``: the command is a
cubic (piecewise-constant jerk, :mod:`.profile`), the first-order tracking error adds one
exponential, saturated and free motion are quadratics, a braking curve squares a speed.
This module owns that form (``F``, the 5-tuple (c0, c1, c2, c3, d) of every piece, or
``AnyF`` of any degree for a condition; the rate ``k`` is passed alongside) and the
instants where such a function changes sign, found by a derivative cascade: the n-th
derivative of ``f`` is ``n! cn + d (-k)ⁿ e^(-kτ)``, monotonic, so it has at most one
root, which bounds the monotonic stretches of every lower derivative; each root is then
bracketed and refined (safeguarded Newton).  Nothing is sampled on a time grid
(docs/architecture.md rule 2).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Final

#: (c0, c1, c2, c3, d): c0 + c1 τ + c2 τ² + c3 τ³ + d·exp(-k τ), the function of every
#: piece of motion.  Of fixed size, so that compiled code keeps it unboxed (five C
#: doubles, no tuple and no float objects; docs/architecture.md "Fast code").
F = tuple[float, float, float, float, float]
#: (c0, c1, ..., cn, d) with n >= 3: a function of any degree, as the conditions of
#: :func:`roots` and :func:`first_true` are (the braking curve of an S-curve command
#: squares a speed: :func:`mul`).  A 5-tuple takes the :data:`F` paths, the same numbers.
AnyF = tuple[float, ...]

#: (not Final: compiled, a Final tuple of floats read in a conditional expression checks
#: as unset and raises NameError, a mypyc 1.19 fault)
ZERO: F = (0.0, 0.0, 0.0, 0.0, 0.0)
INF: Final = math.inf
_ITERATIONS: Final = 100


def const(c: float) -> F:
    return (float(c), 0.0, 0.0, 0.0, 0.0)


def value(f: F, k: float, t: float) -> float:
    """``f(t)``."""
    c0, c1, c2, c3, d = f
    out = c0 + t * (c1 + t * (c2 + t * c3))
    return out + d * math.exp(-k * t) if d else out


def value_any(f: AnyF, k: float, t: float) -> float:
    """:func:`value` of a function of any degree."""
    if len(f) == 5:
        return value(f, k, t)
    out = 0.0
    for c in reversed(f[:-1]):
        out = out * t + c
    d = f[-1]
    if d:
        out += d * math.exp(-k * t)
    return out


def deriv(f: F, k: float) -> F:
    """``f'``."""
    return (f[1], 2.0 * f[2], 3.0 * f[3], 0.0, -k * f[4])


def _deriv_any(f: AnyF, k: float) -> AnyF:
    if len(f) == 5:
        return deriv(f, k)
    poly = tuple(i * c for i, c in enumerate(f[:-1]) if i) + (0.0,)
    return _pad(poly) + (-k * f[-1],)


def _pad(poly: tuple[float, ...]) -> tuple[float, ...]:
    return poly + (0.0,) * (4 - len(poly)) if len(poly) < 4 else poly


def _poly(f: AnyF, n: int) -> tuple[float, ...]:
    return f[:-1] + (0.0,) * (n - len(f) + 1)


def add(f: F, g: F) -> F:
    return (f[0] + g[0], f[1] + g[1], f[2] + g[2], f[3] + g[3], f[4] + g[4])


def _add_any(f: AnyF, g: AnyF) -> AnyF:
    n = max(len(f), len(g)) - 1
    return tuple(a + b for a, b in zip(_poly(f, n), _poly(g, n))) + (f[-1] + g[-1],)


def sub(f: F, g: F) -> F:
    return (f[0] - g[0], f[1] - g[1], f[2] - g[2], f[3] - g[3], f[4] - g[4])


def sub_any(f: AnyF, g: AnyF) -> AnyF:
    """:func:`sub` of functions of any degree (the braking curve)."""
    if len(f) == 5 and len(g) == 5:
        return sub(f, g)
    return _add_any(f, tuple(c * -1.0 for c in g))


def plus(f: F, c: float) -> F:
    """``f + c``."""
    return (f[0] + c, f[1], f[2], f[3], f[4])


def scale(f: F, s: float) -> F:
    return (f[0] * s, f[1] * s, f[2] * s, f[3] * s, f[4] * s)


def spread(f: F, b: float) -> float:
    """A bound of ``|f(τ) - c0|`` on [0, b] (∞ when b is and ``f`` has a τ term)."""
    out = abs(f[4])
    c = f[1]
    if c:
        if math.isinf(b):
            return INF
        out += abs(c) * b
    c = f[2]
    if c:
        if math.isinf(b):
            return INF
        out += abs(c) * math.pow(b, 2.0)
    c = f[3]
    if c:
        if math.isinf(b):
            return INF
        out += abs(c) * math.pow(b, 3.0)
    return out


def abs_bound(f: F, b: float) -> float:
    """A bound of ``|f|`` on [0, b] (∞ when b is and ``f`` has a τ term): |c0| plus
    :func:`spread`, written out."""
    out = abs(f[0]) + abs(f[4])
    c1, c2, c3 = f[1], f[2], f[3]
    if c1 or c2 or c3:
        if math.isinf(b):
            return INF
        if c1:
            out += abs(c1) * b
        if c2:
            out += abs(c2) * math.pow(b, 2.0)
        if c3:
            out += abs(c3) * math.pow(b, 3.0)
    return out


def mul(f: F, g: F) -> AnyF:
    """Product of two polynomials (no exponential part).  Zero coefficients above the
    cubic are dropped: a product of degree 3 or less is a 5-tuple, as every piece's
    function (the braking curve of a standing command: its roots on the 5-tuple path,
    the same numbers, tests/test_expoly.py)."""
    if f[4] or g[4]:
        raise ValueError("mul() takes polynomials only")
    # out[i + j] += f[i] * g[j] for i, then j, ascending, skipping f[i] == 0, written out
    f0, f1, f2, f3 = f[0], f[1], f[2], f[3]
    g0, g1, g2, g3 = g[0], g[1], g[2], g[3]
    o0 = o1 = o2 = o3 = o4 = o5 = o6 = 0.0
    if f0:
        o0 += f0 * g0
        o1 += f0 * g1
        o2 += f0 * g2
        o3 += f0 * g3
    if f1:
        o1 += f1 * g0
        o2 += f1 * g1
        o3 += f1 * g2
        o4 += f1 * g3
    if f2:
        o2 += f2 * g0
        o3 += f2 * g1
        o4 += f2 * g2
        o5 += f2 * g3
    if f3:
        o3 += f3 * g0
        o4 += f3 * g1
        o5 += f3 * g2
        o6 += f3 * g3
    if o6 != 0.0:
        return (o0, o1, o2, o3, o4, o5, o6, 0.0)
    if o5 != 0.0:
        return (o0, o1, o2, o3, o4, o5, 0.0)
    if o4 != 0.0:
        return (o0, o1, o2, o3, o4, 0.0)
    return (o0, o1, o2, o3, 0.0)


def shift(f: F, k: float, a: float) -> F:
    """The same function with its origin moved to ``a``: ``g(τ) = f(a + τ)``."""
    if not a:
        return f
    c0, c1, c2, c3, d = f
    return (c0 + a * (c1 + a * (c2 + a * c3)), c1 + a * (2.0 * c2 + 3.0 * c3 * a),
            c2 + 3.0 * c3 * a, c3, d * math.exp(-k * a) if d else 0.0)


def _shift_any(f: AnyF, k: float, a: float) -> AnyF:
    if len(f) == 5:
        return shift(f, k, a)
    if not a:
        return f
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


def _degree(f: AnyF) -> int:
    for i in range(len(f) - 2, -1, -1):
        if f[i] != 0.0:
            return i
    return -1


def upper_bound(f: AnyF, k: float, a: float, b: float) -> float:
    """A cheap upper bound of ``f`` on [a, b] (used to skip root searches)."""
    if len(f) == 5:
        return _upper_bound5(f, k, a, b)
    g = _shift_any(f, k, a) if a else f
    w = b - a
    out = g[0]
    for i in range(1, len(g) - 1):
        if g[i] > 0.0:
            if math.isinf(w):
                return INF
            out += g[i] * w ** i
    if g[-1] > 0.0:
        out += g[-1]
    return out


def _upper_bound5(f: F, k: float, a: float, b: float) -> float:
    g = shift(f, k, a) if a else f
    w = b - a
    out = g[0]
    g1, g2, g3, gd = g[1], g[2], g[3], g[4]
    if g1 > 0.0 or g2 > 0.0 or g3 > 0.0:
        if math.isinf(w):
            return INF
        if g1 > 0.0:
            out += g1 * w
        if g2 > 0.0:
            out += g2 * math.pow(w, 2.0)
        if g3 > 0.0:
            out += g3 * math.pow(w, 3.0)
    if gd > 0.0:
        out += gd
    return out


def _sign(x: float) -> int:
    return (x > 0.0) - (x < 0.0)


def _limit_sign(f: AnyF) -> int:
    """Sign of ``f`` as τ -> ∞ (k > 0 makes the exponential vanish)."""
    deg = _degree(f)
    if deg >= 0:
        return _sign(f[deg])
    return _sign(f[-1])


def _refine(f: F, k: float, lo: float, hi: float, flo: float) -> float:
    """The root of ``f`` in [lo, hi] where ``f`` is monotonic and changes sign."""
    # value(f) and value(f') written out (the same expressions, no calls): hot path
    c0, c1, c2, c3, d = f
    s1, s2, s3, sd = c1, 2.0 * c2, 3.0 * c3, -k * d      # deriv(f, k)
    t = 0.5 * (lo + hi)
    for _ in range(_ITERATIONS):
        ft = c0 + t * (c1 + t * (c2 + t * c3))
        if d:
            ft = ft + d * math.exp(-k * t)
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
            slope = slope + sd * math.exp(-k * t)
        step = t - ft / slope if slope != 0.0 else lo - 1.0
        t = step if lo < step < hi else 0.5 * (lo + hi)
    return 0.5 * (lo + hi)


def _refine_any(f: AnyF, k: float, lo: float, hi: float, flo: float) -> float:
    """:func:`_refine` for any degree."""
    if len(f) == 5:
        return _refine(f, k, lo, hi, flo)
    df = _deriv_any(f, k)
    t = 0.5 * (lo + hi)
    for _ in range(_ITERATIONS):
        ft = value_any(f, k, t)
        if ft == 0.0:
            return t
        if (ft < 0.0) == (flo < 0.0):
            lo, flo = t, ft
        else:
            hi = t
        if hi - lo <= 1e-15 * max(1.0, abs(hi)):
            break
        slope = value_any(df, k, t)
        step = t - ft / slope if slope != 0.0 else lo - 1.0
        t = step if lo < step < hi else 0.5 * (lo + hi)
    return 0.5 * (lo + hi)


def _bracket_end(f: AnyF, k: float, lo: float, want: int) -> float:
    """A finite ``hi`` > lo with sign(f(hi)) == want, on a monotonic tail."""
    step = max(1.0, abs(lo))
    hi = lo + step
    for _ in range(2000):
        if _sign(value_any(f, k, hi)) == want:
            return hi
        step *= 2.0
        hi = lo + step
        if math.isinf(hi):
            break
    return INF


def _critical(f: AnyF, k: float, a: float, b: float) -> list[float]:
    """Instants in (a, b) where ``f'`` changes sign."""
    df = _deriv_any(f, k)
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


def roots(f: AnyF, k: float, a: float, b: float) -> list[float]:
    """Instants in (a, b) where ``f`` changes sign, ascending (``b`` may be ∞)."""
    if len(f) == 5:
        return roots5(f, k, a, b)
    if b <= a:
        return []
    if k == 0.0 and f[-1]:            # with k == 0 the exponential is the constant d
        f = (f[0] + f[-1],) + f[1:-1] + (0.0,)
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


def roots5(f: F, k: float, a: float, b: float) -> list[float]:
    """:func:`roots` of a piece's function (unboxed when compiled)."""
    if b <= a:
        return []
    c0, c1, c2, c3, d = f
    if k == 0.0 and d:                # with k == 0 the exponential is the constant d
        c0, d = c0 + d, 0.0
    return _roots5(c0, c1, c2, c3, d, k, a, b)


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
        flo = c0 + a * (c1 + a * (c2 + a * c3))
        fhi = c0 + b * (c1 + b * (c2 + b * c3))
        if d:
            flo = flo + d * math.exp(-k * a)
            fhi = fhi + d * math.exp(-k * b)
        if flo == 0.0 or fhi == 0.0 or (flo < 0.0) == (fhi < 0.0):
            return []
        return [_refine((c0, c1, c2, c3, d), k, a, b, flo)]
    return _roots_between((c0, c1, c2, c3, d), k, [a, *critical, b])


def _roots_between(f: AnyF, k: float, cuts: list[float]) -> list[float]:
    """Sign changes of ``f`` on each stretch between consecutive ``cuts`` (on which it
    is monotonic); the last cut may be ∞."""
    found: list[float] = []
    fnext: float | None = None      # f at the previous stretch's (finite) end
    for i in range(len(cuts) - 1):
        lo, hi = cuts[i], cuts[i + 1]
        flo = value_any(f, k, lo) if fnext is None else fnext
        fnext = None
        if math.isinf(hi):
            want = _limit_sign(f)
            if want == 0 or want == _sign(flo) or flo == 0.0:
                continue
            hi = _bracket_end(f, k, lo, want)
            if math.isinf(hi):
                continue
            fhi = value_any(f, k, hi)
        else:
            fhi = fnext = value_any(f, k, hi)
        if flo == 0.0 or fhi == 0.0 or (flo < 0.0) == (fhi < 0.0):
            continue
        found.append(_refine_any(f, k, lo, hi, flo))
    return found


def first_true(conds: Sequence[AnyF], k: float, a: float, b: float) -> float | None:
    """First τ in [a, b) at which every ``cond(τ) > 0``; ``None`` if never.

    The interval is cut at every sign change of every condition; the first stretch
    whose midpoint satisfies all of them starts at the answer.  Conditions whose
    cheap upper bound is <= 0 make the answer ``None`` at once.
    """
    if b <= a:
        return None
    if len(conds) == 1:
        cond = conds[0]
        if len(cond) == 5:
            return _first_true5(cond, k, a, b)
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
            if not value_any(c, k, mid) > 0.0:
                break
        else:
            return lo
    return None


def _first_true5(f: F, k: float, a: float, b: float) -> float | None:
    """:func:`first_true` of one piece-sized condition (most are): taken apart once."""
    if _upper_bound5(f, k, a, b) <= 0.0:
        return None
    found = roots5(f, k, a, b)
    cuts = sorted({a, *found}) if found else [a]
    last = len(cuts) - 1
    for i, lo in enumerate(cuts):
        hi = cuts[i + 1] if i < last else b
        mid = lo + 1.0 if math.isinf(hi) else 0.5 * (lo + hi)
        if value(f, k, mid) > 0.0:
            return lo
    return None


def _all_roots(conds: Iterable[AnyF], k: float, a: float, b: float) -> list[float]:
    out: list[float] = []
    for cond in conds:
        out.extend(roots(cond, k, a, b))
    return out
