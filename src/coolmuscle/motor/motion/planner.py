"""Motion planning: CML motion data to closed-form :class:`~.profile.Profile` objects.

This module owns :class:`Limits`, :class:`Waypoint`, :func:`limits_from_data` and the
planners: point-to-point and merge motion (:func:`plan_moves`, cml-users-guide.txt
2.1, 4.1.1-4.1.3), continuous rotation (:func:`plan_velocity`, 2.1.1
``P=1000000000``), stops (:func:`plan_stop`, ``]``/``}``/``*`` in 2.1.2) and the
closed-form trapezoid time (:func:`minimum_time`).

Every plan is built from *velocity ramps*: from a speed and acceleration to a new
speed with acceleration zero, trapezoidal (K69=0) or jerk-limited (K69>0).  Speeds
inside the planner are magnitudes in the direction of motion; the direction is
applied when segments are emitted.  Ramps never pass through zero speed: a change of
direction is a stop followed by a new start.  The fidelity choices (K69 mapping,
where a merge speed change happens, creep speed, emergency deceleration) are
written down in docs/fidelity.md "Motion".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from ...sim.memo import Key, Memo
from ..state import units
from .profile import Profile, Segment, State, _check_chain

#: K69 value of a pure S-curve (ch. 3 K69, range 0..1024).
SCURVE_MAX = 1024

#: ``*`` "maximum deceleration" (2.1.2): the largest deceleration any motion can be
#: given, A=32767 kpps² (2.1.1) at K44=500 % (ch. 3 K44), in pulses/s².
ESTOP_DECEL = 32767 * 1000.0 * 500 / 100

Piece = tuple[float, float, float]  # (duration s, acceleration at its start, jerk)

_REL_TOL = 1e-12


@dataclass(unsafe_hash=True, slots=True)
class Limits:
    """Speed (pps), acceleration and deceleration (pulses/s²), creep speed (pps, K51)
    and S-curve gain (K69, 0..1024) of one motion.  Immutable by convention."""

    speed: float
    accel: float
    decel: float
    creep: float = 0.0
    scurve: int = 0

    def __post_init__(self) -> None:
        if not (self.speed > 0.0 and self.accel > 0.0 and self.decel > 0.0):
            raise ValueError(f"speed, accel and decel must be > 0: {self!r}")
        if not 0.0 <= self.creep <= self.speed:
            raise ValueError(f"creep must be within 0..speed: {self!r}")
        if not 0 <= self.scurve <= SCURVE_MAX:
            raise ValueError(f"scurve must be within 0..{SCURVE_MAX}: {self!r}")

    @property
    def jerk_accel(self) -> float:
        """Jerk of the acceleration phases (pulses/s³); ``inf`` for a trapezoid."""
        return scurve_jerk(self.accel, self.speed, self.scurve)

    @property
    def jerk_decel(self) -> float:
        """Jerk of the deceleration phases (pulses/s³); ``inf`` for a trapezoid."""
        return scurve_jerk(self.decel, self.speed, self.scurve)

    @property
    def max_jerk(self) -> float:
        """The largest jerk a plan with these limits may use."""
        return max(self.jerk_accel, self.jerk_decel)


@dataclass(init=False, unsafe_hash=True, slots=True)
class Waypoint:
    """A target position (pulses) and the limits of the motion that reaches it."""

    target: float
    limits: Limits

    def __init__(self, target: float, limits: Limits) -> None:
        # written out: built on the hot path (docs/architecture.md "Fast code")
        self.target = target
        self.limits = limits


def scurve_jerk(accel: float, speed: float, scurve: int) -> float:
    """Jerk for K69 = ``scurve`` (docs/fidelity.md "Motion").

    With r = K69/1024, a full speed change 0 -> S at peak acceleration A spends the
    fraction r of its time in the two jerk ramps: J = A²(2 - r) / (r S).  K69=1024
    is a pure S (no constant-acceleration part); K69=0 is a trapezoid (J infinite).
    """
    if scurve <= 0:
        return math.inf
    r = scurve / SCURVE_MAX
    return accel * accel * (2.0 - r) / (r * speed)


def limits_from_data(s_value: int, a_value: int, *, k37: int, k44: int, k51: int,
                     k69: int, decel_a_value: int | None = None) -> Limits:
    """Limits from S and A data (2.1, 2.1.1) and K37, K44, K51, K69 (ch. 3).

    S is in the K37 speed unit, A in kpps²; both are taken as absolute values.  The
    deceleration is A x K44 %, or a second A on the same line (4.1.3).  The creep
    speed K51 is in speed units and never exceeds the speed.  ``ValueError`` for
    S or A of zero.
    """
    unit = units.resolution(k37).speed_unit_pps
    speed = float(abs(s_value) * unit)
    accel = units.accel_to_pps2(abs(a_value))
    if decel_a_value is None:
        decel = accel * k44 / 100.0
    else:
        decel = units.accel_to_pps2(abs(decel_a_value))
    creep = min(float(abs(k51) * unit), speed)
    return Limits(speed, accel, decel, creep, int(k69))


def minimum_time(distance: float, limits: Limits) -> float:
    """Closed-form duration of a trapezoid/triangle move from rest (K69 ignored).

    The move starts at the creep speed c and ends from it (K51):
    v_peak² = c² + 2 A D L / (A + D), capped at S.
    """
    length = abs(distance)
    if length == 0.0:
        return 0.0
    acc, dec, top, c = limits.accel, limits.decel, limits.speed, limits.creep
    lift = 2.0 * acc * dec * length / (acc + dec)
    rise = lift / (math.sqrt(c * c + lift) + c)  # peak - c without cancellation
    if c + rise <= top:
        return rise / acc + rise / dec
    ramps = (top * top - c * c) * (1.0 / (2.0 * acc) + 1.0 / (2.0 * dec))
    return (top - c) / acc + (top - c) / dec + (length - ramps) / top


# -- velocity ramps ----------------------------------------------------------------
def _ramp(u0: float, b0: float, u1: float, lim: Limits) -> list[Piece]:
    """Pieces from speed ``u0`` and acceleration ``b0`` to speed ``u1`` at rest accel.

    Speed increases use ``accel`` and its jerk, decreases ``decel`` and its jerk.
    With S-curve and a start acceleration (re-planning on the fly) the whole ramp
    uses one jerk (:func:`_jerks`), and a start acceleration beyond the limits is
    cut to them at once (docs/fidelity.md "Motion").
    """
    if lim.scurve == 0:
        if u1 == u0:
            return []
        amax = lim.accel if u1 > u0 else -lim.decel
        return [((u1 - u0) / amax, amax, 0.0)]
    b0 = min(max(b0, -lim.decel), lim.accel)
    ja, jd = _jerks(lim, u0, b0)
    if u1 >= u0 + b0 * abs(b0) / (2.0 * ja):
        return _jerk_ramp(u0, b0, u1, lim.accel, ja, 1.0)
    return _jerk_ramp(u0, b0, u1, lim.decel, jd, -1.0)


def _jerks(lim: Limits, u0: float, b0: float) -> tuple[float, float]:
    """(accel jerk, decel jerk) of a ramp starting at speed ``u0``, acceleration ``b0``.

    From a decelerating state the jerk is at least b0²/(2 u0), so that unwinding
    the deceleration does not cross zero speed (the running motion had that much).
    """
    if b0 == 0.0:
        return lim.jerk_accel, lim.jerk_decel
    stiff = lim.max_jerk
    if b0 < 0.0 and u0 > 0.0 and b0 * b0 / (2.0 * u0) > stiff * (1.0 + 1e-6):
        stiff = b0 * b0 / (2.0 * u0)  # (within 1e-6 of the jerk: rounding of the state)
    return stiff, stiff


def _jerk_ramp(u0: float, b0: float, u1: float, amax: float, jerk: float,
               sgn: float) -> list[Piece]:
    """S-curve ramp; in the frame where speed grows (``sgn``) the acceleration goes
    from its start value to a peak (<= amax), holds, and returns to zero."""
    c0 = sgn * b0
    delta = sgn * (u1 - u0)
    full = (c0 + amax) * abs(amax - c0) / (2.0 * jerk) + amax * amax / (2.0 * jerk)
    if delta >= full:
        raw = [(abs(amax - c0) / jerk, c0, math.copysign(jerk, amax - c0)),
               ((delta - full) / amax, amax, 0.0), (amax / jerk, amax, -jerk)]
    else:
        peak = math.sqrt(max(0.0, jerk * delta + c0 * c0 / 2.0))
        raw = [((peak - c0) / jerk, c0, jerk), (peak / jerk, peak, -jerk)]
    return [(d, sgn * a, sgn * j) for d, a, j in raw if d > 0.0]


def _travel(u: float, pieces: Sequence[Piece]) -> float:
    """Distance covered by ``pieces`` starting at speed ``u``."""
    dist = 0.0
    for t, a, j in pieces:
        dist += t * (u + t * (a / 2.0 + t * j / 6.0))
        u += t * (a + t * j / 2.0)
    return dist


def _ramp_travel(u0: float, b0: float, u1: float, lim: Limits) -> float:
    return _travel(u0, _ramp(u0, b0, u1, lim))


def _bisect(f: Callable[[float], float], lo: float, hi: float, target: float) -> float:
    """Largest x found in [lo, hi] with f(x) <= target, f non-decreasing, f(lo) <= target."""
    while hi - lo > _REL_TOL * hi:
        mid = 0.5 * (lo + hi)
        if f(mid) <= target:
            lo = mid
        else:
            hi = mid
    return lo


# -- spans: one stretch between two points without reversal --------------------------
def _span(u0: float, b0: float, u1: float, dist: float, lim: Limits) -> list[Piece]:
    """Pieces covering ``dist`` from (u0, b0) to speed u1, peak speed <= lim.speed.

    Trapezoid: peak² = (2AD·L + D·u0² + A·u1²) / (A + D).  S-curve: the peak is
    found by bisection on the (monotonic) distance; any residual is cruised.
    """
    cap = lim.speed
    if lim.scurve == 0:
        if u0 >= cap:
            peak = cap
        else:
            acc, dec = lim.accel, lim.decel
            free = math.sqrt((2.0 * acc * dec * dist + dec * u0 * u0 + acc * u1 * u1)
                             / (acc + dec))
            peak = min(cap, max(u0, u1, free))
    else:
        def total(v: float) -> float:
            return _ramp_travel(u0, b0, v, lim) + _ramp_travel(v, 0.0, u1, lim)
        peak = cap if total(cap) <= dist else _bisect(total, u1, cap, dist)
    up, down = _ramp(u0, b0, peak, lim), _ramp(peak, 0.0, u1, lim)
    cruise = dist - _travel(u0, up) - _travel(peak, down)
    if peak > 0.0 and cruise > 0.0:
        up.append((cruise / peak, 0.0, 0.0))
    return up + down


def _max_entry(v_next: float, dist: float, lim: Limits, cap: float) -> float:
    """Largest speed <= cap from which a ramp reaches ``v_next`` within ``dist``."""
    if v_next >= cap:
        return cap
    if lim.scurve == 0:
        return min(cap, math.sqrt(v_next * v_next + 2.0 * lim.decel * dist))

    def travel(v: float) -> float:
        return _ramp_travel(v, 0.0, v_next, lim)
    return cap if travel(cap) <= dist else _bisect(travel, v_next, cap, dist)


def _max_exit(u: float, b: float, dist: float, lim: Limits, cap: float) -> float:
    """Largest speed <= cap a ramp from (u, b) reaches within ``dist``."""
    if lim.scurve == 0:
        return cap if u >= cap else min(cap, math.sqrt(u * u + 2.0 * lim.accel * dist))

    def travel(v: float) -> float:
        return _ramp_travel(u, b, v, lim)
    if travel(cap) <= dist:
        return cap
    lo = min(cap, max(0.0, u + b * abs(b) / (2.0 * _jerks(lim, u, b)[0])))
    return lo if travel(lo) > dist else _bisect(travel, lo, cap, dist)


@dataclass(slots=True)
class _Span:
    dist: float
    direction: float
    limits: Limits
    indices: list[int]


def _run_speeds(run: Sequence[_Span], u0: float, b0: float, creep: float,
                moving: bool) -> list[float] | None:
    """Speed at the end of each span of a run (no reversal inside; it ends at the
    creep speed), or ``None`` when a moving start cannot make the first span (from
    rest every run is feasible by construction).

    Backward pass: each passing speed <= both spans' S and low enough to slow down
    in time; forward pass: reachable from the previous one.
    """
    out = [0.0] * len(run)
    out[-1] = creep
    for k in range(len(run) - 2, -1, -1):
        nxt = run[k + 1]
        cap = min(run[k].limits.speed, nxt.limits.speed)
        out[k] = _max_entry(out[k + 1], nxt.dist, nxt.limits, cap)
    u, b = u0, b0
    for k, span in enumerate(run):
        out[k] = min(out[k], _max_exit(u, b, span.dist, span.limits, out[k]))
        if k == 0 and moving and _ramp_travel(u, b, out[0], span.limits) > span.dist:
            return None
        u, b = out[k], 0.0
    return out


# -- building segments -------------------------------------------------------------
class _Builder:
    """Accumulates segments from a start state, advancing time and state exactly."""

    def __init__(self, state: State) -> None:
        self.p, self.v, self.a = (float(x) for x in state)
        self.t = 0.0
        self.segments: list[Segment] = []
        self.passing: list[tuple[float, int]] = []

    @property
    def moving(self) -> bool:
        return self.v != 0.0 or self.a != 0.0

    def add(self, duration: float, a: float, j: float) -> None:
        """Append a segment (one shorter than the clock's resolution is kept: its
        change of speed is invisible to evaluation but keeps the chain exact)."""
        if not duration > 0.0:
            return
        self.segments.append(Segment(self.t, duration, self.p, self.v, a, j))
        if math.isinf(duration):
            self.t = math.inf
            return
        t = duration
        self.p += t * (self.v + t * (a / 2.0 + t * j / 6.0))
        self.v += t * (a + t * j / 2.0)
        self.a = a + j * t
        self.t += t

    def follow(self, pieces: Sequence[Piece], direction: float, end_speed: float) -> None:
        """Emit ramp pieces in ``direction``; land exactly on ``end_speed``."""
        for t, a, j in pieces:
            self.add(t, direction * a, direction * j)
        self.set_speed(direction * end_speed)

    def set_speed(self, v: float) -> None:
        """Set the velocity with zero acceleration (a ramp's end, a creep jump)."""
        self.v, self.a = v, 0.0

    def profile(self, origin_ns: int, start: State, final: float | None) -> Profile:
        return Profile(origin_ns, self.segments, start_state=start,
                       final_position=final, passing_times=self.passing)


def _stop(b: _Builder, lim: Limits) -> None:
    """Decelerate to rest; the last step is the jump from creep speed to 0 (K51)."""
    if not b.moving:
        return
    d = 1.0 if b.v > 0.0 or (b.v == 0.0 and b.a > 0.0) else -1.0
    u = abs(b.v)
    if u > lim.creep or (lim.creep == 0.0 and b.a != 0.0):
        b.follow(_ramp(u, d * b.a, lim.creep, lim), d, lim.creep)
    b.set_speed(0.0)


def _spans(here: float, waypoints: Sequence[Waypoint]) -> list[_Span]:
    """Non-empty stretches between consecutive points; a waypoint equal to the point
    before it is passed together with that point."""
    spans: list[_Span] = []
    for i, w in enumerate(waypoints):
        dist = w.target - here
        if dist == 0.0:
            if spans:
                spans[-1].indices.append(i)
            continue
        spans.append(_Span(abs(dist), math.copysign(1.0, dist), w.limits, [i]))
        here = w.target
    return spans


def _runs(spans: list[_Span]) -> list[list[_Span]]:
    """Group spans into runs of one direction (a reversal ends merge motion, 4.1.2)."""
    runs: list[list[_Span]] = []
    for span in spans:
        if runs and runs[-1][0].direction == span.direction:
            runs[-1].append(span)
        else:
            runs.append([span])
    return runs


def _path(b: _Builder, waypoints: Sequence[Waypoint]) -> None:
    """Emit the whole path; stop first when the start state cannot make it directly."""
    runs = _runs(_spans(b.p, waypoints))
    last = len(waypoints) - 1
    if b.moving and (not runs or b.v * runs[0][0].direction <= 0.0):
        _stop(b, waypoints[0].limits)
        return _path(b, waypoints)
    for r, run in enumerate(runs):
        d = run[0].direction
        creep = min(span.limits.creep for span in run)
        if r == 0 and b.moving:
            u0, b0 = abs(b.v), d * b.a
        else:
            u0, b0 = creep, 0.0
        speeds = _run_speeds(run, u0, b0, creep, r == 0 and b.moving)
        if speeds is None:
            _stop(b, waypoints[0].limits)
            return _path(b, waypoints)
        b.set_speed(d * u0)
        b.a = d * b0
        for span, out in zip(run, speeds):
            b.follow(_span(u0, b0, out, span.dist, span.limits), d, out)
            b.passing.extend((b.t, i) for i in span.indices if i != last)
            u0, b0 = out, 0.0
        b.set_speed(0.0)
    return None


# -- public planners ---------------------------------------------------------------
def plan_moves(start_state: State, waypoints: Sequence[Waypoint], origin_ns: int,
               plans: Plans | None = None) -> Profile:
    """Point-to-point (one waypoint) or merge motion (several), 4.1.1-4.1.3.

    Merge motion passes each point without stopping; a span's S is never exceeded
    between its two points, so a speed increase starts at the passing point and a
    decrease is completed by it.  A reversal stops at the point (4.1.2).  From a
    moving start that cannot make the first point the motor stops, then returns.

    ``plans``: where plans are looked up and kept (a chain's, ``dynamics.MotionMemos``):
    the segments are relative to the origin and immutable, so a machine cycle that
    repeats its moves plans each one once (the same numbers: the plan depends on
    nothing else).
    """
    if not waypoints:
        raise ValueError("plan_moves needs at least one waypoint")
    # Plain numbers as the key: hashing and comparing floats stays in C (the
    # dataclasses' generated __hash__/__eq__ would run interpreted).
    key: Key = (tuple(start_state), tuple([_waypoint_key(w) for w in waypoints]))
    found = None if plans is None else plans.get(key)
    if found is None:
        b = _Builder(start_state)
        _path(b, waypoints)
        found = (tuple(b.segments), tuple(b.passing))
        _check_chain(found[0])
        if plans is not None:
            plans.put(key, found)
    return Profile(origin_ns, found[0], start_state=start_state,
                   final_position=float(waypoints[-1].target), passing_times=found[1],
                   checked=True)


def _waypoint_key(w: Waypoint) -> tuple[float, float, float, float, float, int]:
    lim = w.limits
    return (w.target, lim.speed, lim.accel, lim.decel, lim.creep, lim.scurve)


#: Plans by (start state, waypoints as plain numbers): the segments and passing times.
Plans = Memo[Key, tuple[tuple[Segment, ...], tuple[tuple[float, int], ...]]]


def plan_velocity(start_state: State, velocity_pps: float, limits: Limits,
                  origin_ns: int) -> Profile:
    """Continuous rotation (2.1.1 ``P=1000000000``) at a signed speed; endless.

    A sign change stops (creep rule) and starts again; velocity 0 is a stop.
    """
    b = _Builder(start_state)
    if velocity_pps == 0.0:
        _stop(b, limits)
        return b.profile(origin_ns, start_state, b.p)
    d = math.copysign(1.0, velocity_pps)
    target = abs(velocity_pps)
    if b.v * d < 0.0 or (b.v == 0.0 and b.a * d < 0.0):
        _stop(b, limits)
    if not b.moving:
        b.set_speed(d * min(limits.creep, target))
    b.follow(_ramp(abs(b.v), d * b.a, target, limits), d, target)
    b.add(math.inf, 0.0, 0.0)
    return b.profile(origin_ns, start_state, None)


def plan_stop(start_state: State, decel: float, origin_ns: int, scurve: int = 0, *,
              creep: float = 0.0, speed: float | None = None) -> Profile:
    """Decelerate to rest at ``decel`` (``]``/``}``: the motion's deceleration;
    ``*``: :data:`ESTOP_DECEL`, 2.1.2).

    ``scurve`` is K69; its jerk uses ``speed`` (the motion's S; default the current
    speed).  With ``creep`` (K51) the stop ends with the jump from creep speed to 0.
    """
    v = abs(start_state[1])
    ref = speed if speed else (v if v > 0.0 else 1.0)
    lim = Limits(ref, max(decel, abs(start_state[2])), decel, min(creep, ref), scurve)
    b = _Builder(start_state)
    _stop(b, lim)
    return b.profile(origin_ns, start_state, b.p)


def plan_emergency_stop(start_state: State, origin_ns: int) -> Profile:
    """``*``: stop at :data:`ESTOP_DECEL`, no S-curve, no creep (2.1.2)."""
    return plan_stop(start_state, ESTOP_DECEL, origin_ns)
