"""External encoder on inputs 1 and 2 (cml-users-guide.txt 5.4; ch. 3 K71, K72; 6.6 ?76).

This module owns :class:`Gearing` (where the encoder pulses come from: the load the
motor drives, with ratio, slip and backlash, or an independent motion) with
:func:`gearing_from_config` for the machine file's ``[axis.encoder]`` table, and
:class:`ExternalEncoder`: the count (``?76`` ``Ecnt.n=``, V states ``"CT"`` /
``"Ecnt"``) and the index (K71=1-3) and feedback (K71=4) operations.

Counting (K71 table): A-phase types count each rising edge of A, up or down by
the direction of rotation (or by B as a direction signal); a rising edge of A comes
at every whole encoder cycle going forward and half a cycle later going back.  A&B
types count the four edges of a cycle ("sub-count") and the count is the integral
part of sub-count / 4.  Both are :class:`~coolmuscle.motor.motion.trajectory.Schmitt`
quantizers on the encoder phase; backlash widens their hysteresis by half the play.
Nothing is sampled: counts are read in closed form and the index stop is a solved
instant.  Choices: docs/fidelity.md "External encoder".
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ...sim.kernel import NS_PER_S, PRIO_MOTION, Timer
from ..motion.planner import Limits
from ..motion.trajectory import Piece, Schmitt, Timeline, Track

if TYPE_CHECKING:
    from ..core import MotorCore

A_PHASE_TYPES = (1, 2, 5, 6)
INDEX_TYPES = (1, 2, 3)
FEEDBACK_TYPE = 4
#: CM1 K63 (Appendix A): 1 phase A only, 2 A and B, 3 A and B with Fx/Cx: counting.
_CM1_K63 = {0: 0, 1: 5, 2: 7, 3: 7}


@dataclass(frozen=True)
class Gearing:
    """Where the encoder pulses come from (machine file ``[axis.encoder]``).

    ``kind="load"``: an encoder turning ``ratio`` times per motor revolution, less
    ``slip`` (0..1), with ``backlash`` motor pulses of play; ``ppr`` is its pulses per
    revolution (default: what K72 says).  ``kind="independent"``: ``rate`` pulses/s
    from ``start`` to ``stop`` seconds, whatever the motor does.  ``kind="none"``:
    nothing connected.
    """

    kind: str = "load"
    ratio: float = 1.0
    ppr: int | None = None
    slip: float = 0.0
    backlash: float = 0.0
    rate: float = 0.0
    start: float = 0.0
    stop: float | None = None


def _num(table: Mapping[str, Any], key: str, default: float) -> float:
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"[axis.encoder] {key} must be a finite number")
    return float(value)


#: The keys of each kind of ``[axis.encoder]`` (docs/machine-file.md).
_ENCODER_KEYS: dict[str, frozenset[str]] = {
    "load": frozenset({"kind", "ratio", "ppr", "slip", "backlash"}),
    "independent": frozenset({"kind", "rate", "start", "stop", "ppr"}),
    "none": frozenset({"kind", "ppr"}),
}


def gearing_from_config(table: Mapping[str, Any]) -> Gearing:
    """A :class:`Gearing` from the machine file's ``[axis.encoder]`` table (ValueError)."""
    kind = str(table.get("kind", "load")).lower()
    if kind not in _ENCODER_KEYS:
        raise ValueError(f"[axis.encoder] kind must be load, independent or none, not {kind!r}")
    unknown = sorted(str(k) for k in table if k not in _ENCODER_KEYS[kind])
    if unknown:                 # a misspelt key is an error, not a silent default
        raise ValueError(f"[axis.encoder] kind {kind!r}: unknown key {unknown[0]!r} "
                         f"(known: {', '.join(sorted(_ENCODER_KEYS[kind]))})")
    ppr = table.get("ppr")
    if ppr is not None and (isinstance(ppr, bool) or not isinstance(ppr, int) or ppr <= 0):
        raise ValueError("[axis.encoder] ppr must be a positive integer")
    slip = _num(table, "slip", 0.0)
    if not 0.0 <= slip < 1.0:
        raise ValueError("[axis.encoder] slip must be within 0 <= slip < 1")
    backlash = _num(table, "backlash", 0.0)
    if backlash < 0.0:
        raise ValueError("[axis.encoder] backlash must be >= 0")
    stop = table.get("stop")
    return Gearing(kind, _num(table, "ratio", 1.0), ppr, slip, backlash,
                   _num(table, "rate", 0.0), _num(table, "start", 0.0),
                   None if stop is None else _num(table, "stop", 0.0))


class _Clock:
    """A quantizer driven by an independent linear phase E(t) (kind="independent")."""

    def __init__(self, schmitt: Schmitt, gearing: Gearing, now: int) -> None:
        self.schmitt = schmitt
        self.rate = gearing.rate
        self.start = round(gearing.start * NS_PER_S)
        self.stop = None if gearing.stop is None else round(gearing.stop * NS_PER_S)
        self.since = now
        self.schmitt.init(self.value(now))
        self.initial = self.schmitt.state

    def value(self, t: int) -> float:
        t = max(t, self.start)
        if self.stop is not None:
            t = min(t, self.stop)
        return self.rate * (t - self.start) / NS_PER_S

    def state_at(self, t: int) -> int:
        probe = Schmitt(self.schmitt.width, self.schmitt.up, self.schmitt.down, self.initial)
        probe.move_to(self.value(max(t, self.since)))
        return probe.state

    def reach_time(self, target: int, now: int) -> int | None:
        s = self.schmitt
        threshold = target * s.width + s.up if target > self.state_at(now) \
            else (target + 1) * s.width - s.down
        if self.rate == 0.0:
            return None
        t = self.start + math.ceil((threshold / self.rate) * NS_PER_S)
        if t < now or (self.stop is not None and t > self.stop):
            return now if self.state_at(now) == target else None
        return t


class ExternalEncoder:
    """K71/K72 external encoder of one motor."""

    def __init__(self, motor: MotorCore, timeline: Timeline) -> None:
        self.motor = motor
        self.timeline = timeline
        self.gearing = Gearing()
        self.type = 0
        self.offset = 0            # count carried over a reconfiguration
        self.base = 0              # quantizer state at the last reconfiguration
        self.track: Track | None = None
        self.clock: _Clock | None = None
        self._index_state: int | None = None
        self._index_timer: Timer | None = None
        self._config: tuple[object, ...] | None = None
        motor.params.on_change(self._param_changed)
        timeline.listeners.append(self._trajectory_changed)
        self.reconfigure()

    # -- configuration ----------------------------------------------------------------
    def encoder_type(self) -> int:
        """The CM2 K71 type the parameters select (CM1 K63 maps onto it)."""
        if self.motor.firmware.name == "cm1":
            return _CM1_K63.get(self.motor.k(63), 0)
        return self.motor.k(71)

    def resolution(self) -> int:
        """K72 (CM1: K88), the encoder resolution the motor is told."""
        return self.motor.k(88 if self.motor.firmware.name == "cm1" else 72)

    def set_gearing(self, gearing: Gearing) -> None:
        """Connect the machine's encoder (machine file, tests)."""
        self.gearing = gearing
        self.reconfigure()

    def quadrature(self) -> bool:
        return self.type not in A_PHASE_TYPES

    def scale(self) -> float:
        """Encoder cycles per raw motor pulse."""
        g = self.gearing
        ppr = g.ppr if g.ppr is not None else self.resolution()
        return g.ratio * (1.0 - g.slip) * ppr / self.motor.resolution.pulses_per_rev

    def _schmitt(self) -> Schmitt:
        play = abs(self.scale()) * self.gearing.backlash / 2 if self.gearing.kind == "load" else 0
        if self.quadrature():
            return Schmitt(0.25, play, play)
        return Schmitt(1.0, play, 0.5 + play)

    def reconfigure(self) -> None:
        """K71/K72/K37 or the gearing changed: keep the count, restart counting.

        Writing a parameter with the value it has changes nothing (the quantizer keeps
        its hysteresis)."""
        config = (self.encoder_type(), self.resolution(), self.motor.k(37), self.gearing)
        if config == self._config:
            return
        self._config = config
        self.offset = self.count()
        self.cancel_index()
        if self.track is not None:
            self.track.close()
        self.track = self.clock = None
        self.type = self.encoder_type()
        if self.type == 0 or self.gearing.kind == "none":
            return
        if self.gearing.kind == "independent":
            self.clock = _Clock(self._schmitt(), self.gearing, self.timeline.now())
            self.base = self.clock.initial
        else:
            self.track = Track(self.timeline, self._schmitt(), scale=self.scale(), raw=True)
            self.base = self.track.schmitt.state

    def _param_changed(self, k: int, old: int, new: int) -> None:
        del old, new
        if k in ((63, 88, 37) if self.motor.firmware.name == "cm1" else (71, 72, 37)):
            self.reconfigure()

    def uses_input(self, number: int) -> bool:
        """Whether input ``number`` carries encoder pulses (its functions are off, 5.4)."""
        if self.type == 0:
            return False
        return number == 1 or (number == 2 and self.type not in (1, 5))

    # -- the count ----------------------------------------------------------------------
    def _state(self, t: int | None = None) -> int | None:
        now = self.timeline.now()
        if self.track is not None:
            return self.track.state() if t is None or t >= now else self.track.state_at(t)
        if self.clock is not None:
            return self.clock.state_at(now if t is None else t)
        return None

    def _count_of(self, state: int) -> int:
        sub = state - self.base
        return self.offset + (int(sub / 4) if self.quadrature() else sub)

    def count(self, t: int | None = None) -> int:
        """The external encoder count now (or at an earlier ``t``, for traces)."""
        state = self._state(t) if self.type else None
        return self.offset if state is None else self._count_of(state)

    def frequency(self) -> float:
        """Encoder pulses per second now (RT3 ``Fx``)."""
        if self.clock is not None:
            return self.clock.rate
        if self.track is None:
            return 0.0
        return self.scale() * self.motor.axis.sign * self.motor.axis.velocity()

    # -- index and feedback operations (5.4.1, 5.4.2) -----------------------------------------
    def handles_go(self, target: int, s_value: int, limits: Limits) -> bool:
        """``^`` with K71=1-3 (index) or 4 (feedback on a load encoder); else False."""
        if self.type in INDEX_TYPES:
            self._start_index(target, s_value, limits)
            return True
        if self.type == FEEDBACK_TYPE and self.track is not None:
            self._feedback_move(target, limits)
            return True
        return False

    def _stay(self, limits: Limits) -> None:
        m = self.motor
        here = m.axis.target()
        m.move_to([(here if math.isfinite(here) else m.axis.position(), limits)])

    def _target_state(self, target: int, up: bool) -> int:
        """The quantizer state at which the count first becomes ``target``."""
        want = target - self.offset
        if not self.quadrature():
            return self.base + want
        if up:
            sub = 4 * want if want > 0 else 4 * want - 3
        else:
            sub = 4 * want + 3 if want >= 0 else 4 * want
        return self.base + sub

    def _start_index(self, target: int, s_value: int, limits: Limits) -> None:
        """Rotate at S until the count reaches P, then stop without correcting (5.4.1)."""
        m = self.motor
        self.cancel_index()
        if not m.can_move():
            return
        count = self.count()
        if count == target:
            self._stay(limits)
            return
        up = target > count
        raw_dir = 1 if up else -1
        if self.track is not None and self.scale() < 0:
            raw_dir = -raw_dir
        m.run_continuous(raw_dir * m.axis.sign * abs(s_value), limits)
        self._index_state = self._target_state(target, up)
        self._schedule_index()

    def _schedule_index(self) -> None:
        if self._index_timer is not None:
            self._index_timer.cancel()
            self._index_timer = None
        if self._index_state is None:
            return
        now = self.timeline.now()
        if self.track is not None:
            at = self.track.reach_time(self._index_state)
        elif self.clock is not None:
            at = self.clock.reach_time(self._index_state, now)
        else:
            at = None
        if at is not None:
            self._index_timer = self.motor.kernel.schedule_at(
                at, self._index_reached, priority=PRIO_MOTION, name="encoder-index")

    def _index_reached(self) -> None:
        self._index_timer = None
        self._index_state = None
        self.motor.stop()

    def cancel_index(self) -> None:
        """Forget a running index operation (its motion was replaced)."""
        if self._index_timer is not None:
            self._index_timer.cancel()
        self._index_timer = None
        self._index_state = None

    def _trajectory_changed(self, old: Piece, new: Piece) -> None:
        del old
        if self._index_state is None:
            return
        if new.profile.end_ns is None:
            self._schedule_index()      # still rotating (a new speed): solve again
        else:
            self.cancel_index()         # stopped, alarm, another motion

    def _feedback_move(self, target: int, limits: Limits) -> None:
        """Full closed loop on the load count (5.4.2): the motor goes where the load
        encoder reads ``target``, the middle of that count's first sub-count."""
        m = self.motor
        assert self.track is not None
        if not m.can_move():
            return
        if self.count() == target:
            self._stay(limits)
            return
        state = self.track.state()
        goal = self.base + 4 * (target - self.offset)
        s = self.track.schmitt
        phase = (goal + 0.5) * s.width + (s.up if goal > state else -s.down)
        user = self.track.position_for(self.timeline.piece, phase)
        if user is None:
            return
        m.move_to([(user, limits)])
