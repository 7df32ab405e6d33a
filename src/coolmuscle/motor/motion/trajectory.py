"""The actual shaft position over time, and the hysteretic signals derived from it.

This module owns :class:`Piece` (one trajectory the axis followed: profile, tracking
solution and user coordinates), :class:`Schmitt` (a quantizer with hysteresis) and
:class:`Track` / :class:`Timeline`, which keep quantizers in step with the axis
without sampling: the actual position is monotonic between the instants where the
servo reverses (the shaft motion's velocity zeros), so a
quantizer is advanced by the end points of those runs, and an edge time is solved
by bisection on one run.

Two users: the rotation pulse output (cml-users-guide.txt 5.2, ch. 3 K24, K34=7;
:mod:`.pulses`) and the external encoder count (5.4, K71; :mod:`.encoder`).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

from ...sim.kernel import NS_PER_MS, NS_PER_S
from .profile import Profile

if TYPE_CHECKING:
    from .axis import Axis

#: Largest number of edges solved for one export (a trace of a long fast run).
MAX_EDGES: Final = 200_000


@dataclass(init=False, unsafe_hash=True, slots=True)
class Piece:
    """One trajectory of the axis from ``start`` (kernel ns) until the next one
    (immutable by convention)."""

    start: int
    profile: Profile
    tracking: Any           # the servo model's solution (servo.Tracking or a motion)
    zero: float
    sign: int

    def __init__(self, start: int, profile: Profile, tracking: Any, zero: float,
                 sign: int) -> None:
        # written out: built on the hot path (docs/architecture.md "Fast code")
        self.start = start
        self.profile = profile
        self.tracking = tracking
        self.zero = zero
        self.sign = sign

    def position(self, t: int) -> float:
        """Actual position in user pulses at kernel time ``t``."""
        return self.sign * (self.raw_position(t) - self.zero)

    def raw_position(self, t: int) -> float:
        """Actual position in raw encoder pulses (the shaft, whatever ``|2`` did)."""
        shaft = getattr(self.tracking, "position_at", None)
        if callable(shaft):
            return float(shaft(t))
        error: float = self.tracking.error_at(t)
        return self.profile.position_at(t) - error

    def user_of(self, raw: float) -> float:
        """A raw position in this piece's user coordinates."""
        return self.sign * (raw - self.zero)

    def velocity(self, t: int) -> float:
        """Actual speed, user pulses/s."""
        velocity: float = self.tracking.actual_velocity_at(t)
        return self.sign * velocity

    def turns(self, t0: int, t1: int) -> list[int]:
        """Instants in (t0, t1) where the actual motion may reverse.

        Asks the servo model: ``velocity_zeros`` (first-order tracking,
        :mod:`.servo`), or the sign changes of each piece's speed of a piecewise
        shaft motion (``pieces``, ``to_ns``; the load model); else a 1 ms scan.
        """
        zeros = getattr(self.tracking, "velocity_zeros", None)
        if callable(zeros):
            return list(zeros(t0, t1))
        if hasattr(self.tracking, "pieces") and hasattr(self.tracking, "to_ns"):
            return _piecewise_turns(self.tracking, t0, t1)
        return _sampled_turns(self, t0, t1)

    def runs(self, t0: int, t1: int) -> Iterator[tuple[int, int]]:
        """Consecutive (ta, tb) covering [t0, t1] on which the position is monotonic."""
        cuts = [t0, *self.turns(t0, t1), t1]
        for ta, tb in zip(cuts, cuts[1:]):
            if tb > ta:
                yield ta, tb

    def first_reach(self, x: float, t0: int, t1: int) -> int | None:
        """First kernel time in (t0, t1] at which the position reaches ``x``."""
        for ta, tb in self.runs(t0, t1):
            hit = _reach_on_run(self, x, ta, tb)
            if hit is not None:
                return hit
        return None


def piece_of(axis: Axis) -> Piece:
    """The trajectory the axis follows now."""
    return Piece(axis.kernel.now, axis.profile, axis.tracking, axis.zero, axis.sign)


def _piecewise_turns(motion: Any, t0: int, t1: int) -> list[int]:
    """Piece boundaries and speed sign changes of a piecewise closed-form motion."""
    from . import expoly  # noqa: PLC0415  (the load model's closed forms)
    rel0 = (t0 - motion.origin_ns) / NS_PER_S
    rel1 = (t1 - motion.origin_ns) / NS_PER_S
    if hasattr(motion, "cover"):
        motion.cover(rel1)                # a motion solved in part: on to t1
    out: list[int] = []
    for p in motion.pieces:
        a, b = max(rel0, p.start), min(rel1, p.end)
        if a >= b:
            continue
        cuts = [0.0, *expoly.roots5(p.vel(), p.k, a - p.start, b - p.start)]
        out.extend(t for t in (motion.to_ns(p, tau) for tau in cuts) if t0 < t < t1)
    return sorted(set(out))


def _sampled_turns(piece: Piece, t0: int, t1: int) -> list[int]:
    """Fallback for a servo model without ``velocity_zeros``: 1 ms scan + bisection."""
    out: list[int] = []
    prev_t, prev_v = t0, piece.velocity(t0)
    t = t0
    while t < t1:
        t = min(t + NS_PER_MS, t1)
        v = piece.velocity(t)
        if prev_v != 0.0 and v != 0.0 and (prev_v < 0.0) != (v < 0.0):
            lo, hi = prev_t, t
            while hi - lo > 1:
                mid = (lo + hi) // 2
                if (piece.velocity(mid) < 0.0) == (prev_v < 0.0):
                    lo = mid
                else:
                    hi = mid
            if t0 < hi < t1:
                out.append(hi)
        prev_t, prev_v = t, v
    return out


def _reach_on_run(piece: Piece, x: float, ta: int, tb: int) -> int | None:
    """Smallest t in (ta, tb] with the position at or past ``x`` (monotonic run)."""
    pa, pb = piece.position(ta), piece.position(tb)
    if pb == pa or not min(pa, pb) <= x <= max(pa, pb) or pa == x:
        return None
    up = pb > pa
    lo, hi = ta, tb
    while hi - lo > 1:
        mid = (lo + hi) // 2
        p = piece.position(mid)
        if (p >= x) if up else (p <= x):
            hi = mid
        else:
            lo = mid
    return hi


@dataclass(slots=True)
class Schmitt:
    """Quantizer with hysteresis: state c holds while the input stays within
    [c·width - down, (c+1)·width + up]; leaving it moves c by whole steps.

    With ``up = down = h`` the band boundaries are the multiples of ``width``
    and a switch happens ``h`` past each (5.2 "±1/5000 hysteresis").
    """

    width: float
    up: float = 0.0
    down: float = 0.0
    state: int = 0

    def init(self, x: float) -> None:
        """Set the state from a position without history."""
        self.state = math.floor(x / self.width)

    def rise(self) -> float:
        """Input at which the state goes up by one."""
        return (self.state + 1) * self.width + self.up

    def fall(self) -> float:
        """Input at which the state goes down by one."""
        return self.state * self.width - self.down

    def move_to(self, x: float) -> None:
        """The state after a monotonic move ending at ``x``."""
        if x >= self.rise():
            self.state = math.floor((x - self.up) / self.width)
        elif x <= self.fall():
            self.state = math.ceil((x + self.down) / self.width) - 1

    def copy(self) -> Schmitt:
        return Schmitt(self.width, self.up, self.down, self.state)


class Track:
    """A :class:`Schmitt` driven by ``scale * position + offset`` of one timeline.

    Kept current lazily (:meth:`state`), advanced at every trajectory change, with
    checkpoints while the timeline records so past states can be read back.
    """

    def __init__(self, timeline: Timeline, schmitt: Schmitt, *, scale: float = 1.0,
                 offset: float = 0.0, raw: bool = False) -> None:
        self.timeline = timeline
        self.schmitt = schmitt
        self.scale = scale
        self.offset = offset
        self.raw = raw
        self.done = timeline.now()
        self.schmitt.init(self.value(timeline.piece, self.done))
        self.checkpoints: list[tuple[int, int, Piece]] = []
        self._times: list[int] = []
        self._checkpoint(timeline.piece)
        timeline.tracks.append(self)

    def value(self, piece: Piece, t: int) -> float:
        """The quantizer's input: scale x (raw or user) position + offset."""
        x = piece.raw_position(t) if self.raw else piece.position(t)
        return self.scale * x + self.offset

    def position_for(self, piece: Piece, value: float) -> float | None:
        """The user position at which the input is ``value`` (None: no dependence)."""
        if self.scale == 0.0:
            return None
        x = (value - self.offset) / self.scale
        return piece.user_of(x) if self.raw else x

    def close(self) -> None:
        """Stop following the axis."""
        if self in self.timeline.tracks:
            self.timeline.tracks.remove(self)

    def _checkpoint(self, piece: Piece) -> None:
        entry = (self.done, self.schmitt.state, piece)
        if not self.timeline.recording:
            self.checkpoints, self._times = [], []
        elif self._times and self._times[-1] == self.done:
            self.checkpoints.pop()
            self._times.pop()
        self.checkpoints.append(entry)
        self._times.append(self.done)

    def _advance(self, schmitt: Schmitt, piece: Piece, t0: int, t1: int) -> None:
        for _, tb in piece.runs(t0, t1):
            schmitt.move_to(self.value(piece, tb))

    def state(self) -> int:
        """The state now."""
        now = self.timeline.now()
        if now > self.done:
            self._advance(self.schmitt, self.timeline.piece, self.done, now)
            self.done = now
        return self.schmitt.state

    def switch(self, old: Piece, new: Piece, now: int) -> None:
        """The axis changes trajectory at ``now`` (called by the timeline)."""
        if now > self.done:
            self._advance(self.schmitt, old, self.done, now)
        self.done = max(self.done, now)
        if abs(self.value(new, now) - self.value(old, now)) > 1e-6 * max(1.0, abs(self.scale)):
            self.schmitt.init(self.value(new, now))   # a coordinate jump (|2), not motion
        self._checkpoint(new)

    def state_at(self, t: int) -> int:
        """The state at an earlier (or the current) instant ``t``."""
        base = self._base(t)
        if base is None:
            return self.schmitt.state
        start, state, piece = base
        probe = self.schmitt.copy()
        probe.state = state
        if t > start:
            self._advance(probe, piece, start, t)
        return probe.state

    def _base(self, t: int) -> tuple[int, int, Piece] | None:
        if not self.checkpoints:
            return None
        i = bisect_right(self._times, t) - 1
        return self.checkpoints[max(i, 0)]

    def edges(self, t0: int, t1: int, limit: int = MAX_EDGES) -> list[tuple[int, int]]:
        """(time, new state) of every state change in (t0, t1], solved on each run."""
        out: list[tuple[int, int]] = []
        starts = self._times
        for i, (start, _, piece) in enumerate(self.checkpoints):
            end = starts[i + 1] if i + 1 < len(starts) else t1
            lo, hi = max(start, t0), min(end, t1)
            if hi <= lo:
                continue
            probe = self.schmitt.copy()
            probe.state = self.state_at(lo)
            for ta, tb in piece.runs(lo, hi):
                self._run_edges(probe, piece, ta, tb, out)
                if len(out) >= limit:
                    return out
        return out

    def _run_edges(self, probe: Schmitt, piece: Piece, ta: int, tb: int,
                   out: list[tuple[int, int]]) -> None:
        end = self.value(piece, tb)
        while True:
            target = probe.rise() if end >= probe.rise() else (
                probe.fall() if end <= probe.fall() else None)
            if target is None:
                return
            x = self.position_for(piece, target)
            hit = None if x is None else piece.first_reach(x, ta, tb)
            if hit is None:
                probe.move_to(end)
                out.append((tb, probe.state))
                return
            probe.state += 1 if target == probe.rise() else -1
            out.append((hit, probe.state))
            ta = hit

    def reach_time(self, target: int) -> int | None:
        """When the state first reaches ``target`` on the current trajectory."""
        now = self.timeline.now()
        current = self.state()
        if current == target:
            return now
        s = self.schmitt
        if target > current:
            threshold = target * s.width + s.up
        else:
            threshold = (target + 1) * s.width - s.down
        piece = self.timeline.piece
        x = self.position_for(piece, threshold)
        return None if x is None else piece.first_reach(x, now, _horizon(piece, now))


def _horizon(piece: Piece, now: int) -> int:
    """How far ahead a crossing is searched: the end of the command plus settling,
    or a day of continuous rotation."""
    end = piece.profile.end_ns
    if end is None:
        return now + 86_400 * 1_000_000_000
    return max(end, now) + 10 * 1_000_000_000


class Timeline:
    """The trajectories of one axis as :class:`Piece` objects, and the tracks on them."""

    def __init__(self, axis: Axis) -> None:
        self.axis = axis
        self.piece = piece_of(axis)
        self.tracks: list[Track] = []
        self.recording = False
        self.listeners: list[Callable[[Piece, Piece], None]] = []
        axis.trajectory_listeners.append(self._on_trajectory)

    def now(self) -> int:
        return self.axis.kernel.now

    def record(self, on: bool = True) -> None:
        """Keep checkpoints so states can be read back for a trace."""
        self.recording = on

    def _on_trajectory(self) -> None:
        axis, old = self.axis, self.piece
        if axis.profile is old.profile and axis.motion is old.tracking \
                and axis.zero == old.zero and axis.sign == old.sign:
            return
        now = axis.kernel.now
        new = Piece(now, axis.profile, axis.motion, axis.zero, axis.sign)
        if self.tracks:
            for track in list(self.tracks):
                track.switch(old, new, now)
        self.piece = new
        if self.listeners:                   # a copy only when someone listens
            for listener in list(self.listeners):
                listener(old, new)

    def position(self) -> float:
        return self.piece.position(self.now())

    def piece_at(self, t: int) -> Piece:
        """The trajectory followed at ``t`` (earlier ones from the axis history while a
        trace records; else the current one)."""
        history = self.axis.history
        if t >= self.piece.start or not history:
            return self.piece
        i = max(bisect_right([h[0] for h in history], t) - 1, 0)
        return Piece(*history[i])

