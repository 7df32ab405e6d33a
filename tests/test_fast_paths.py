"""The cheaper paths of the hot code against the exact ones they replace.

* The overload watcher (ch. 3 K57) walks the stretches beyond rated torque at once; the
  reference below is the watcher as it was, one kernel event per crossing.  Both run on
  twin chains through random moves and csp target streams: the same reports at the same
  instants, the same shaft.
* The temperature watcher (6.6 ?71, Ux=128) asks a per-piece bound before integrating:
  with and without the bound it answers the same instant.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from hypothesis import given, settings
from hypothesis import strategies as st

from coolmuscle.chain.daisy import Chain
from coolmuscle.motor.motion import expoly as xp
from coolmuscle.motor.supervision import alarms, thermal
from coolmuscle.sim.kernel import NS_PER_MS, seconds

if TYPE_CHECKING:
    from coolmuscle.motor.motion.axis import Axis


class EventOverload(alarms._AlarmWatch):
    """The overload watcher as it was first written: an event where the torque goes beyond
    rated ("enter"), one where it comes back ("leave"), the alarm K57 ms after an
    enter without a leave."""

    bit = alarms.Ux.OVERLOAD
    mask = int(bit)

    def __init__(self, motor: object) -> None:
        super().__init__(motor)  # type: ignore[arg-type]
        self.since: int | None = None
        self._action = ""

    def next_time(self, axis: Axis, after_ns: int) -> int | None:
        if not self.active(axis):
            self.since = None
            return None
        per = axis.motion.drive.percent_per_accel
        rated = 100.0 / per if per > 0.0 else float("inf")
        motion = axis.motion
        if self.since is None:
            self._action = "enter"
            if motion.peak("torque") <= rated:
                return None
            return motion.first(after_ns, *alarms._beyond(lambda p: p.torque, rated),
                                skip=lambda p: motion.reach(p, "torque") <= rated)
        deadline = self.since + self.motor.k(57) * 1_000_000 + 1
        back = motion.first(after_ns, lambda p: [xp.plus(p.torque, rated),
                                                 xp.plus(xp.scale(p.torque, -1.0), rated)],
                            horizon_ns=deadline)
        if back is not None and back <= deadline:
            self._action = "leave"
            return back
        self._action = "alarm"
        return max(deadline, after_ns)

    def fire(self, axis: Axis) -> None:
        now = self.motor.kernel.now
        if self._action == "enter":
            self.since = now
        elif self._action == "leave":
            self.since = None
        else:
            self.since = None
            super().fire(axis)


def twin(exact: bool, setup: str) -> tuple[Chain, list[tuple[int, str]]]:
    chain = Chain()
    if exact:
        axis = chain.motors[1].axis
        for watcher in list(axis.watchers):
            if isinstance(watcher, alarms.OverloadWatch):
                index = axis.watchers.index(watcher)
                axis.remove_watcher(watcher)
                reference = EventOverload(chain.motors[1])
                axis.add_watcher(reference, index)
    events: list[tuple[int, str]] = []
    chain.subscribe(lambda e: events.append((e.time, e.text)))
    chain.execute("K23.1=1")
    chain.execute(setup)
    return chain, events


moves = st.lists(st.tuples(st.integers(-30_000, 30_000), st.integers(1, 400),
                           st.integers(1, 200), st.integers(0, 400)), min_size=1, max_size=5)


@settings(max_examples=25, deadline=None)
@given(moves=moves, k57=st.integers(1, 300), limit=st.integers(30, 100),
       stopper=st.one_of(st.none(), st.integers(500, 20_000)),
       load=st.integers(0, 250))
def test_ch3_k57_overload_walk_matches_one_event_per_crossing(
        moves: list[tuple[int, int, int, int]], k57: int, limit: int,
        stopper: int | None, load: int) -> None:
    """Stoppers in the way and a load torque (fault injection) push the torque beyond
    rated, for less or more than K57 ms."""
    runs = []
    for exact in (True, False):
        chain, events = twin(exact, f"K57.1={k57}, M.1={limit}")
        if stopper is not None:
            chain.motors[1].geometry.stopper_cw = float(stopper)
        if load:
            chain.inject_fault(1, "overload", torque=load)
        trace = []
        for target, speed, accel, gap_ms in moves:
            if chain.motors[1].alarm:
                chain.execute("|.1")               # alarm reset (2.1.2), then servo on
                chain.execute("(.1")
            chain.execute(f"S.1={speed}, A.1={accel}, P.1={target}")
            chain.execute("^.1")
            chain.kernel.advance(gap_ms * NS_PER_MS)
            trace.append((chain.motors[1].position(), chain.motors[1].alarm))
        chain.kernel.advance(seconds(3))
        runs.append((events, trace, chain.motors[1].axis.raw_actual()))
    assert runs[0] == runs[1]


@settings(max_examples=10, deadline=None)
@given(amplitude=st.integers(100, 60_000), k57=st.integers(1, 50),
       limit=st.integers(3, 100), period=st.integers(200, 4000))
def test_a_csp_stream_gives_the_same_motion_and_reports_with_fewer_events(
        amplitude: int, k57: int, limit: int, period: int) -> None:
    """Cyclic synchronous position: a target every 1 ms; the walk gives what the events gave."""
    runs = []
    for exact in (True, False):
        chain, events = twin(exact, f"K57.1={k57}, M.1={limit}")
        stream = chain.target_stream(1)
        shaft = []
        for i in range(600):
            stream.push(round(amplitude * (1.0 - math.cos(2.0 * math.pi * i / period)) / 2))
            chain.kernel.advance(NS_PER_MS)
            shaft.append((chain.motors[1].axis.raw_actual(), chain.motors[1].alarm))
        runs.append((events, shaft, chain.kernel.events_run))
    assert runs[0][:2] == runs[1][:2]
    assert runs[1][2] <= runs[0][2]


@settings(max_examples=30, deadline=None)
@given(moves=moves, temp=st.floats(40.0, 84.9), alarm=st.floats(41.0, 120.0),
       rise=st.floats(0.0, 400.0), tau=st.floats(0.5, 900.0))
def test_temperature_bound_never_changes_the_alarm_instant(
        moves: list[tuple[int, int, int, int]], temp: float, alarm: float, rise: float,
        tau: float) -> None:
    chain = Chain()
    motor = chain.motors[1]
    motor.thermal.rise_at_rated, motor.thermal.time_constant = rise, tau
    for target, speed, accel, gap_ms in moves:
        chain.execute(f"S.1={speed}, A.1={accel}, P.1={target}")
        chain.execute("^.1")
        now = chain.kernel.now
        motor.thermal.reset(temp, now)
        bounded = motor.thermal.first_above(motor.axis.motion, now, alarm)
        exact = _without_bound(motor.thermal, motor.axis.motion, now, alarm)
        assert bounded == exact
        chain.kernel.advance(gap_ms * NS_PER_MS)


def _without_bound(model: thermal.Thermal, motion: object, now: int, limit: float) -> int | None:
    saved = thermal.Thermal._may_exceed
    thermal.Thermal._may_exceed = lambda *args: True  # type: ignore[assignment, method-assign]
    try:
        return model.first_above(motion, now, limit)  # type: ignore[arg-type]
    finally:
        thermal.Thermal._may_exceed = saved  # type: ignore[method-assign]
