"""A servo (CM2) in cyclic synchronous position mode: one target each cycle.

ethercat-bridge-users-guide.txt 6.3 (a target every 1 ms); docs/fidelity.md "csp between
two targets" (the command ramps to each target over the cycle, as a drive interpolates
between the targets of a cyclic mode) and "A stream's motion, solved to its next target"
(the motion of a target is solved as far as the next one; the part after it only when a
stream stops or something looks there, with the same numbers and instants).
"""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from coolmuscle.chain import Chain
from coolmuscle.device.api import Event
from coolmuscle.motor.motion import expoly as xp
from coolmuscle.motor.motion.dynamics import SAT, Drive, Motion, Piece
from coolmuscle.motor.motion.profile import Profile, Segment
from fixtures import collect_events

MS = 1_000_000
#: 0.1 ms: the samples compared between a motion solved in part and in full.
STEP = MS // 10


def _ramp_target(i: int) -> int:
    """A cosine move of 4,000 pulses in 2 s and back (the bench's csp ramp)."""
    return round(2000 * (1 - math.cos(math.pi * i / 2000)))


def _run(in_full: bool, k56: int | None = None, jump: int = 0,
         cycles: int = 300) -> tuple[list[tuple[float, ...]], list[Event], Chain]:
    """A CM2 given a target each 1 ms for ``cycles`` cycles (the last ``jump`` pulses
    further), then none for 200 ms; the state every 0.1 ms and the motor's events."""
    chain = Chain(None, 1, firmware="cm2")
    motor = chain.motors[1]
    motor.axis.solve_in_full = in_full
    if k56 is not None:
        chain.set_param(1, 56, k56)
    chain.kernel.run(until=10 * MS)
    events = collect_events(chain)
    stream = chain.target_stream(1, MS)
    samples: list[tuple[float, ...]] = []

    def sample(until: int) -> None:
        while chain.kernel.now < until:
            chain.kernel.advance(STEP)
            axis = motor.axis
            samples.append((chain.kernel.now, axis.raw_actual(), axis.raw_velocity(),
                            axis.raw_command(), axis.position_error(), axis.torque_percent(),
                            motor.status))

    for i in range(1, cycles + 1):
        stream.push(_ramp_target(i) + (jump if i == cycles else 0))
        sample(chain.kernel.now + MS)
    sample(chain.kernel.now + 200 * MS)
    return samples, events, chain


def _transcript(events: list[Event]) -> list[tuple[int, str, str]]:
    return [(e.time, e.kind, e.text) for e in events]


def test_6_3_a_servo_ramps_its_command_to_each_target_over_the_cycle() -> None:
    chain = Chain(None, 1, firmware="cm2")
    axis = chain.motors[1].axis
    chain.kernel.run(until=10 * MS)
    stream = chain.target_stream(1, MS)
    for i in range(1, 501):
        stream.push(2 * i)                                   # 2,000 pps
        start = chain.kernel.now
        chain.kernel.advance(MS // 2)
        assert axis.raw_command() == 2 * i - 1               # halfway along the ramp
        assert axis.motion.mode_at(chain.kernel.now) != SAT  # never at the torque limit
        chain.kernel.advance(MS // 2)
        assert chain.kernel.now == start + MS and axis.raw_command() == 2 * i
    lag = 1000 - axis.raw_actual()
    kp = axis.motion.drive.kp
    assert abs(lag - 2000.0 / kp) < 0.05                     # the loop's lag at 2,000 pps
    chain.kernel.advance(200 * MS)
    snap = chain.snapshot(1)
    assert snap.position == 1000 and snap.status & 0x08 and not snap.status & 0x01


def test_a_streamed_motion_is_solved_to_its_next_target_then_in_full_when_none_comes() -> None:
    chain = Chain(None, 1, firmware="cm2")
    axis = chain.motors[1].axis
    chain.kernel.run(until=10 * MS)
    stream = chain.target_stream(1, MS)
    stream.push(5)
    motion = axis.motion
    assert motion.open and motion.frontier_ns() == chain.kernel.now + MS
    assert motion.pieces[-1].end == 1e-3                      # the ramp's piece, no further
    chain.kernel.advance(MS - 1)
    assert axis.motion is motion and motion.open
    chain.kernel.advance(1)                                   # no new target at the frontier
    assert axis.motion is motion and not motion.open
    assert math.isinf(motion.pieces[-1].end)                  # solved to its end


def test_solved_in_part_or_in_full_a_stream_moves_and_reports_the_same_to_the_bit() -> None:
    lazy, lazy_events, _ = _run(in_full=False)
    full, full_events, _ = _run(in_full=True)
    assert lazy == full
    assert _transcript(lazy_events) == _transcript(full_events)
    assert any("Ux.1=8" in text for _, _, text in _transcript(lazy_events))   # in position


def test_ch3_k56_an_alarm_beyond_the_solved_part_comes_at_the_same_instant() -> None:
    """A last target 3,000 pulses further: Pe passes K56 x 100 after the cycle the
    target came in, found when the stream has stopped (ch. 3 K56, Ux=1)."""
    lazy, lazy_events, chain = _run(in_full=False, k56=20, jump=3000, cycles=50)
    full, full_events, _ = _run(in_full=True, k56=20, jump=3000, cycles=50)
    assert chain.motors[1].alarm & 0x01
    assert lazy == full
    assert _transcript(lazy_events) == _transcript(full_events)


@settings(max_examples=60, deadline=None)
@given(kp=st.floats(50.0, 3000.0), a_limit=st.floats(1e4, 1e7),
       friction=st.floats(0.0, 5e3), load=st.floats(-5e3, 5e3),
       position=st.floats(-50.0, 50.0), velocity=st.floats(-2e4, 2e4),
       start=st.floats(-50.0, 50.0), target=st.floats(-200.0, 200.0),
       period_us=st.integers(100, 4000), looks=st.lists(st.integers(0, 20_000), max_size=4))
def test_a_motion_solved_in_part_is_the_motion_solved_in_full(
        kp: float, a_limit: float, friction: float, load: float, position: float,
        velocity: float, start: float, target: float, period_us: int,
        looks: list[int]) -> None:
    """Whatever is asked of it and when, a motion solved up to a horizon gives the pieces,
    values and instants of the same motion solved at once (dynamics.Motion)."""
    drive = Drive(kp=kp, a_limit=a_limit, a_friction=friction, a_load=load, v_max=3e5)
    origin, period = 7 * MS, period_us * 1000
    span = period / 1e9
    profile = Profile(origin, (Segment(0.0, span, start, (target - start) / span, 0.0, 0.0),),
                      final_position=target)
    full = Motion(profile, origin, position, velocity, drive)
    part = Motion(profile, origin, position, velocity, drive, horizon_ns=origin + period)
    frontier = part.frontier_ns()
    if frontier is not None:
        assert frontier >= origin + period - 1
        assert part.position_at(frontier) == full.position_at(frontier)
        assert part.velocity_at(frontier) == full.velocity_at(frontier)
        assert part.torque_at(frontier) == full.torque_at(frontier)
    for look in looks:                                       # evaluated anywhere, any order
        t = origin + look * 1000
        assert part.position_at(t) == full.position_at(t)
        assert part.error_at(t) == full.error_at(t)
    part.complete()
    assert not part.open
    assert [repr(p) for p in part.pieces] == [repr(p) for p in full.pieces]
    assert part.peak("torque") == full.peak("torque")
    assert part.within(target, 1.0, origin) == full.within(target, 1.0, origin)


def _within_by_both_sides(motion: Motion, center: float, window: float,
                          after_ns: int) -> int | None:
    """The K55 search written as its definition: the first instant at which the
    position is below ``center + window`` and above ``center - window`` together."""
    def inside(piece: Piece) -> list[xp.F]:
        off = xp.sub(piece.pos, xp.const(center))
        return [xp.sub(xp.const(window), off), xp.sub(off, xp.const(-window))]
    return motion.first_of(after_ns, (inside,))


@settings(max_examples=120, deadline=None)
@given(kp=st.floats(50.0, 3000.0), a_limit=st.floats(1e4, 1e7),
       friction=st.floats(0.0, 5e3), position=st.floats(-300.0, 300.0),
       velocity=st.floats(-2e4, 2e4), target=st.floats(-300.0, 300.0),
       center=st.floats(-300.0, 300.0), window=st.integers(-1, 50).map(float),
       period_us=st.integers(100, 4000), after_us=st.integers(0, 20_000))
def test_k55_in_position_is_the_first_instant_within_the_window_on_both_sides(
        kp: float, a_limit: float, friction: float, position: float, velocity: float,
        target: float, center: float, window: float, period_us: int,
        after_us: int) -> None:
    """Ch. 3 K55: in position is the first instant the shaft is within the window of the
    target.  The search (one side's root only, or at once when already inside) gives
    the instant the two-sided definition gives, and the shaft is inside there.  K55 is
    a whole number of pulses (-1: a window that holds nothing, as 0 does)."""
    drive = Drive(kp=kp, a_limit=a_limit, a_friction=friction, a_load=0.0, v_max=3e5)
    origin, period = 7 * MS, period_us * 1000
    span = period / 1e9
    profile = Profile(origin, (Segment(0.0, span, position, (target - position) / span,
                                       0.0, 0.0),), final_position=target)
    motion = Motion(profile, origin, position, velocity, drive)
    after = origin + after_us * 1000
    found = motion.within(center, window, after)
    assert found == _within_by_both_sides(motion, center, window, after)
    if found is not None:
        assert found >= after
        assert abs(motion.position_at(found) - center) <= window + 1e-3   # (a ns later)
