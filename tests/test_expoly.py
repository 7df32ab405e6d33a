"""Roots of polynomial-plus-exponential functions (motor/expoly.py), against dense sampling.

The servo and load model (docs/fidelity.md "Servo, load and alarms") finds every switching
instant with :func:`coolmuscle.motor.motion.expoly.roots` / ``first_true``; here they are checked
against a brute-force scan of the same functions.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from coolmuscle.motor.motion import expoly as xp

coef = st.floats(-1e3, 1e3, allow_nan=False).map(lambda x: 0.0 if abs(x) < 1e-3 else x)


def _sign_changes(f: xp.F, k: float, b: float, n: int = 200_001) -> np.ndarray:
    t = np.linspace(0.0, b, n)
    poly = np.zeros_like(t)
    for c in reversed(f[:-1]):
        poly = poly * t + c
    values = poly + f[-1] * np.exp(-k * t)
    s = np.sign(values)
    idx = np.nonzero(s[:-1] * s[1:] < 0)[0]
    return t[idx]


@settings(max_examples=150, deadline=None)
@given(c=st.tuples(coef, coef, coef, coef, coef), k=st.floats(0.1, 50.0))
def test_roots_match_a_dense_scan(c: tuple[float, ...], k: float) -> None:
    f = tuple(c)
    found = xp.roots(f, k, 0.0, 2.0)
    for r in found:
        assert 0.0 < r < 2.0
        scale = max(1.0, *(abs(x) for x in f))
        assert abs(xp.value(f, k, r)) <= 1e-7 * scale
    scanned = _sign_changes(f, k, 2.0)
    # every sign change on the grid has a root within a grid step of it
    for t in scanned:
        assert any(abs(t - r) <= 2.0 / 200_000 * 2 for r in found), (t, found)


def test_roots_of_a_cubic_plus_exponential_by_hand() -> None:
    # (τ - 1)(τ - 2)(τ - 3) = τ³ - 6τ² + 11τ - 6, no exponential
    assert [round(r, 12) for r in xp.roots((-6.0, 11.0, -6.0, 1.0, 0.0), 0.0, 0.0, 10.0)] \
        == [1.0, 2.0, 3.0]
    # 1 - 2 e^{-τ}: root at ln 2
    (r,) = xp.roots((1.0, 0.0, 0.0, 0.0, -2.0), 1.0, 0.0, math.inf)
    assert math.isclose(r, math.log(2.0), rel_tol=1e-12)


def test_roots_on_an_endless_stretch() -> None:
    # τ² - 1e6: one root at 1000 on [0, ∞)
    (r,) = xp.roots((-1e6, 0.0, 1.0, 0.0, 0.0), 0.0, 0.0, math.inf)
    assert math.isclose(r, 1000.0, rel_tol=1e-12)
    assert xp.roots((1.0, 0.0, 0.0, 0.0, 5.0), 3.0, 0.0, math.inf) == []


def test_first_true_needs_every_condition() -> None:
    # τ > 1 and τ < 3 and sin-free: the first instant both hold is 1
    above, below = (-1.0, 1.0, 0.0, 0.0, 0.0), (3.0, -1.0, 0.0, 0.0, 0.0)
    assert math.isclose(xp.first_true([above, below], 0.0, 0.0, 10.0), 1.0)
    assert xp.first_true([above, below], 0.0, 4.0, 10.0) is None
    assert xp.first_true([above], 0.0, 2.0, 10.0) == 2.0


def test_shift_mul_and_bounds() -> None:
    f = (1.0, -2.0, 0.5, 0.25, 3.0)
    g = xp.shift(f, 2.0, 0.7)
    for t in (0.0, 0.3, 1.9):
        assert math.isclose(xp.value(g, 2.0, t), xp.value(f, 2.0, t + 0.7), rel_tol=1e-12)
    sq = xp.mul((1.0, 2.0, 0.0, 1.0, 0.0), (1.0, 2.0, 0.0, 1.0, 0.0))
    assert math.isclose(xp.value_any(sq, 0.0, 1.5), (1.0 + 3.0 + 1.5 ** 3) ** 2)
    for t in np.linspace(0.0, 2.0, 50):
        assert abs(xp.value(f, 2.0, float(t))) <= xp.abs_bound(f, 2.0)
        assert xp.value(f, 2.0, float(t)) <= xp.upper_bound(f, 2.0, 0.0, 2.0)


@settings(max_examples=300, deadline=None)
@given(u0=st.floats(-1e4, 1e4), u1=st.floats(-1e6, 1e6), e0=st.floats(-50.0, 50.0),
       e1=st.floats(-1e4, 1e4), e2=st.floats(-1e6, 1e6), ab=st.floats(1e3, 1e7),
       s=st.sampled_from([-1.0, 1.0]), end=st.one_of(st.floats(1e-6, 0.1), st.just(math.inf)))
def test_a_braking_curve_of_degree_two_is_the_same_on_the_5_tuple_path(
        u0: float, u1: float, e0: float, e1: float, e2: float, ab: float, s: float,
        end: float) -> None:
    """mul() drops zero coefficients above the cubic; the braking curve of a standing
    command (dynamics._brake_exit: u linear, so u² quadratic) then takes the 5-tuple
    path with the very roots and first instants of the padded any-degree form."""
    u, eps = (u0, u1, 0.0, 0.0, 0.0), (e0, e1, e2, 0.0, 0.0)
    short = xp.sub_any(xp.mul(u, u), xp.scale(eps, 2.0 * ab * s))
    padded = short[:4] + (0.0,) * 3 + short[4:]
    assert len(short) == 5
    assert xp.roots(short, 300.0, 1e-9, end) == xp.roots(padded, 300.0, 1e-9, end)
    cond = xp.scale(u, s)
    assert xp.first_true([cond, short], 300.0, 1e-9, end) == \
        xp.first_true([cond, padded], 300.0, 1e-9, end)
    assert (xp.upper_bound(short, 300.0, 1e-9, end) <= 0.0) == \
        (xp.upper_bound(padded, 300.0, 1e-9, end) <= 0.0)



def _series(out: float, coefs: dict[int, float], b: float) -> float:
    """``out`` + c_i·b**i, term by term in rising order (∞ when b is): a bound's
    series written with ``**``."""
    if coefs and math.isinf(b):
        return math.inf
    for i, c in coefs.items():
        out += c * b ** i
    return out


@settings(max_examples=300, deadline=None)
@given(f=st.tuples(coef, coef, coef, coef, coef), k=st.floats(0.1, 50.0),
       a=st.one_of(st.just(0.0), st.floats(0.0, 2.0)),
       w=st.one_of(st.floats(0.0, 1e3), st.just(math.inf)))
def test_the_bounds_are_their_power_series_to_the_last_bit(
        f: xp.F, k: float, a: float, w: float) -> None:
    """spread, abs_bound and the 5-tuple upper_bound give the numbers of their series
    written with ``**`` exactly (they take ``math.pow``: compiled, ``**`` on floats is a
    generic call; the same C ``pow`` either way)."""
    terms = {i: abs(f[i]) for i in (1, 2, 3) if f[i]}
    assert xp.spread(f, w) == _series(abs(f[4]), terms, w)
    assert xp.abs_bound(f, w) == _series(abs(f[0]) + abs(f[4]), terms, w)
    g = xp.shift(f, k, a) if a else f
    rising = {i: g[i] for i in (1, 2, 3) if g[i] > 0.0}
    expected = _series(g[0], rising, (a + w) - a)
    if g[4] > 0.0 and not math.isinf(expected):
        expected += g[4]
    assert xp.upper_bound(f, k, a, a + w) == expected
