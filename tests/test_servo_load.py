"""The servo and load model: tracking error, torque limit lag, stoppers,
coasting when free, and the CM1 stepper (docs/fidelity.md "Servo, load and alarms").

cml-users-guide.txt 6.6 ?95 (Pe), ?98 (Ix), 2.1.1 "M" (torque limit, % of the maximum
torque); cm-banks-rt3.txt 3.1 "Torque – Position Control" (with M0 the motor "will always
attempt to 'catch up' to its calculated position").
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from coolmuscle.chain.daisy import Chain
from coolmuscle.motor.motion import expoly as xp
from coolmuscle.motor.motion.dynamics import CONTACT, LOST, SNAP_TIME, TRACK, Motion
from coolmuscle.motor.motor import Motor
from coolmuscle.sim.kernel import NS_PER_S, ms, seconds
from fixtures import ChainFactory, new_chain


def _samples(motion: Motion, t0: int, t1: int, n: int = 4000) -> list[int]:
    return [int(t) for t in np.linspace(t0, t1, n)]


def _check_newton(motion: Motion, t0: int, t1: int) -> None:
    """Between switching instants the shaft accelerates by torque - friction - load."""
    d = motion.drive
    for piece in motion.pieces:
        a = max(piece.start, (t0 - motion.origin_ns) / NS_PER_S)
        b = min(piece.end, (t1 - motion.origin_ns) / NS_PER_S)
        if b - a < 1e-4:
            continue
        for tau in np.linspace(a - piece.start, b - piece.start, 7)[1:-1]:
            acc = xp.value(xp.deriv(piece.vel(), piece.k), piece.k, tau)
            vel = xp.value(piece.vel(), piece.k, tau)
            torque = xp.value(piece.torque, piece.k, tau)
            friction = math.copysign(d.a_friction, vel) if abs(vel) > 1e-6 else None
            if piece.mode in (TRACK, "sat", "brake", "vsat") and friction is not None:
                assert math.isclose(acc, torque - friction - d.a_load,
                                    rel_tol=1e-6, abs_tol=1e-3 * d.a_limit), piece


def _continuous(motion: Motion) -> None:
    for prev, nxt in zip(motion.pieces, motion.pieces[1:]):
        tau = prev.end - prev.start
        p0, p1 = xp.value(prev.pos, prev.k, tau), xp.value(nxt.pos, nxt.k, 0.0)
        assert abs(p0 - p1) <= 1e-6 * max(1.0, abs(p0)), (prev, nxt)
        if nxt.mode != CONTACT and prev.exit not in ("wall_hi", "wall_lo"):
            v0, v1 = xp.value(prev.vel(), prev.k, tau), xp.value(nxt.vel(), nxt.k, 0.0)
            snap = SNAP_TIME * motion.drive.a_limit       # a mismatch closed at once
            assert abs(v0 - v1) <= 1e-5 * max(1.0, abs(v0)) + snap + 1e-6, (prev, nxt)


def test_6_6_pe_is_speed_over_loop_gain_while_cruising(make_chain: ChainFactory) -> None:
    chain = make_chain()
    motor = chain.motors[1]
    chain.execute("S.1=100, A.1=100, P.1=10000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(0.5))
    assert chain.execute("?95.1") == ["Pe.1=33"]          # 10 000 pps / 300 per s
    assert chain.execute("?97.1") == ["Sx.1=100"]
    assert abs(motor.axis.position() - (0.5 * 10000 - 500 - 33.33)) < 0.5


def test_tracking_matches_a_numerical_integration_of_the_loop(make_chain: ChainFactory) -> None:
    chain = make_chain()
    motor = chain.motors[1]
    chain.execute("K69.1=600, K51.1=3")
    chain.execute("S.1=120, A.1=300, P.1=7000")
    chain.execute("^.1")
    motion, profile = motor.axis.motion, motor.axis.profile
    dt, e, t = 1e-5, 0.0, 0.0
    checks = {round(x, 5) for x in np.linspace(0.01, 0.8, 40)}
    worst = 0.0
    while t < 0.8:                                   # RK4 on e' = v_cmd - kp e
        def f(time: float, err: float) -> float:
            return profile.velocity_at(int(round(time * NS_PER_S))) - motor.plant.kp * err
        k1 = f(t, e)
        k2 = f(t + dt / 2, e + dt / 2 * k1)
        k3 = f(t + dt / 2, e + dt / 2 * k2)
        k4 = f(t + dt, e + dt * k3)
        e += dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += dt
        if round(t, 5) in checks:
            worst = max(worst, abs(motion.error_at(int(round(t * NS_PER_S))) - e))
    assert worst < 0.05


def test_2_1_1_torque_limit_m_makes_the_motor_lag_and_catch_up(make_chain: ChainFactory) -> None:
    chain = make_chain(plant={"load_inertia": 1.0e-3})           # 220 times the rotor
    motor = chain.motors[1]
    chain.execute("S.1=100, A.1=100, P.1=10000, M.1=20")  # 20 % of 300 % rated = 60 %
    reports: list[tuple[int, str]] = []
    chain.subscribe(lambda ev: reports.append((ev.time, ev.text)))
    chain.execute("^.1")
    motion, start = motor.axis.motion, chain.kernel.now
    end = start + seconds(3)
    torques = [abs(motion.torque_percent_at(t)) for t in _samples(motion, start, end)]
    errors = [motion.error_at(t) for t in _samples(motion, start, end)]
    assert max(torques) <= 60.0 + 1e-6                     # clamped at the limit
    assert max(torques) > 59.9                             # and it is reached
    assert max(errors) > 500                               # the shaft lags ...
    _check_newton(motion, start, end)
    _continuous(motion)
    chain.kernel.run(until=end)
    assert reports and reports[0][1] == "Ux.1=8"
    assert reports[0][0] > seconds(1.1)                    # ... so it arrives late
    assert motor.position() == 10000 and abs(motor.axis.position_error()) < 0.5


def test_m0_written_while_moving_applies_at_once(make_chain: ChainFactory) -> None:
    chain = make_chain(plant={"load_inertia": 2.0e-4})
    motor = chain.motors[1]
    chain.execute("S.1=100, A.1=100, P.1=10000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(0.02))
    assert motor.torque() > 30
    chain.execute("M.1=5")                                 # 15 % of rated from now on
    chain.kernel.run(until=seconds(0.05))
    assert abs(motor.torque()) <= 15


def _toward_a_stopper(make_chain: ChainFactory) -> tuple[Chain, Motor]:
    """A CM2 moving toward a stopper at 3000 pulses, far beyond it (K56 = 100)."""
    chain = make_chain()
    motor = chain.motors[1]
    motor.geometry.stopper_cw = 3000.0
    motor.axis.refresh()
    chain.execute("K56.1=100, S.1=50, A.1=100, P.1=20000")
    chain.execute("^.1")
    return chain, motor


def test_stopper_contact_stops_the_shaft_pe_grows_torque_at_the_limit(
        make_chain: ChainFactory) -> None:
    chain, motor = _toward_a_stopper(make_chain)
    motion, start = motor.axis.motion, chain.kernel.now
    assert max(motion.position_at(t) for t in _samples(motion, start, start + seconds(2))) \
        <= 3000.0 + 1e-6
    chain.kernel.run(until=seconds(1.0))
    assert motor.axis.mode() == CONTACT
    assert motor.position() == 3000
    assert chain.execute("?98.1") == ["Ix.1=300"]          # M=100: the maximum torque
    pe1 = motor.axis.position_error()
    chain.kernel.run(until=seconds(1.2))
    assert math.isclose(motor.axis.position_error() - pe1, 0.2 * 5000, rel_tol=1e-6)


def test_servo_off_the_shaft_coasts_on_friction(make_chain: ChainFactory) -> None:
    chain = make_chain()
    motor = chain.motors[1]
    chain.execute("S.1=100, A.1=100, P.1=100000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(0.5))
    x0, v0 = motor.axis.position(), motor.axis.velocity()
    chain.execute(").1")
    decel = motor.axis.motion.drive.a_friction
    chain.kernel.run(until=seconds(1.5))
    assert chain.execute("?99.1") == ["Ux.1=16"]
    assert chain.execute("?98.1") == ["Ix.1=0"]
    assert chain.execute("?95.1") == ["Pe.1=0"]
    assert math.isclose(motor.axis.position() - x0, v0 * v0 / (2 * decel), rel_tol=1e-6)


def test_cm1_stepper_has_no_tracking_error_within_its_torque(make_chain: ChainFactory) -> None:
    chain = make_chain(firmware="cm1")
    motor = chain.motors[1]
    assert motor.axis.enabled            # CM1 K68 is the S-curve function, not motor free
    chain.execute("S.1=100, A.1=100, P.1=10000")
    chain.execute("^.1")
    assert motor.axis.moving
    motion, start = motor.axis.motion, chain.kernel.now
    assert all(motion.error_at(t) == 0.0 for t in _samples(motion, start, start + seconds(1.2),
                                                            200))
    chain.kernel.run(until=seconds(1.1))
    assert chain.execute("?99.1") == ["Ux.1=8"]
    assert chain.execute("?96.1") == ["Px.1=10000"]


def test_cm1_stepper_loses_steps_beyond_its_torque(make_chain: ChainFactory) -> None:
    chain = make_chain(firmware="cm1", plant={"load_inertia": 2.0e-3})
    motor = chain.motors[1]
    events: list[str] = []
    chain.subscribe(lambda ev: events.append(ev.text))
    chain.execute("S.1=100, A.1=100, P.1=10000")
    chain.execute("^.1")
    assert motor.axis.mode() == LOST
    chain.kernel.run(until=seconds(2))
    assert "Ux.1=8" not in events                           # it never gets there
    assert motor.position() < 100 and motor.axis.position_error() > 9000


@settings(max_examples=40, deadline=None)
@given(inertia=st.floats(0.0, 3e-3), friction=st.floats(0.0, 0.2), m=st.integers(5, 100),
       s=st.integers(5, 300), a=st.integers(10, 2000), target=st.integers(-50000, 50000))
def test_any_load_and_limit_settles_at_the_target(inertia: float, friction: float, m: int,
                                                  s: int, a: int, target: int) -> None:
    chain = new_chain(plant={"load_inertia": inertia, "coulomb_friction": friction})
    motor = chain.motors[1]
    chain.execute(f"K56.1=32767, K57.1=10000, S.1={s}, A.1={a}, M.1={m}, P.1={target}")
    chain.execute("^.1")
    motion = motor.axis.motion
    assert len(motion.pieces) < 400
    _continuous(motion)
    limit = motor.drive().a_limit * motion.drive.percent_per_accel
    start = chain.kernel.now
    for t in _samples(motion, start, start + seconds(30), 500):
        assert abs(motion.torque_percent_at(t)) <= limit * (1 + 1e-9) + 1e-9
    stuck = motion.drive.a_limit <= motion.drive.a_friction
    if not stuck:
        chain.kernel.run(until=seconds(abs(target) / (s * 100) + 20))
        assert abs(motor.axis.position() - target) <= 5


def test_6_6_ix_is_friction_while_cruising_and_zero_at_rest(make_chain: ChainFactory) -> None:
    chain = make_chain()
    motor = chain.motors[1]
    chain.execute("S.1=100, A.1=100, P.1=10000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(0.5))
    assert motor.axis.torque_percent() == pytest.approx(100 * 0.004 / 0.32, rel=1e-6)
    chain.kernel.run(until=seconds(2))
    assert chain.execute("?98.1") == ["Ix.1=0"] and abs(motor.axis.torque_percent()) < 1e-9


@settings(max_examples=40, deadline=None)
@example(steps=[(0.0, -35, 17), (0.05, -42, 6)], inertia=0.0002, m=10)  # brake -> vzero jump
@given(steps=st.lists(st.tuples(st.sampled_from([0.0, 1e-9, 0.0031, 0.05, 0.3, 1.0, "arrive"]),
                                st.integers(-3000, 3000), st.integers(5, 200)),
                      min_size=2, max_size=8),
       inertia=st.sampled_from([0.0, 2e-4]), m=st.sampled_from([100, 10]))
def test_replanning_at_any_moment_keeps_the_motion_finite(
        steps: list[tuple[object, int, int]], inertia: float, m: int) -> None:
    """New targets arriving at arbitrary instants, also the very instant a move comes in
    position (where Pe and the speed are nearly zero), never chatter."""
    chain = new_chain(plant={"load_inertia": inertia})
    motor = chain.motors[1]
    chain.execute(f"K56.1=32767, K57.1=10000, A.1=100, M.1={m}")
    for delay, target, s in steps:
        if delay == "arrive":
            chain.kernel.run_until(lambda: not motor.axis.moving, seconds(30))
        else:
            chain.kernel.run(until=chain.kernel.now + seconds(float(delay)))  # type: ignore[arg-type]
        chain.execute(f"S.1={s}, P.1={target}")
        chain.execute("^.1")
        assert len(motor.axis.motion.pieces) < 200
        _continuous(motor.axis.motion)
    chain.kernel.run(until=chain.kernel.now + seconds(60))
    assert abs(motor.axis.position() - steps[-1][1]) <= 5


def test_a_repeated_move_reuses_its_solution_with_exactly_the_same_numbers(
        make_chain: ChainFactory) -> None:
    """docs/performance.md: a move solved once is reused when the machine repeats it
    (same drive, same command relative to where it starts); the reused motion is the
    one a fresh solve gives, to the last bit, and the same move elsewhere differs only
    by where it is."""
    chain = make_chain(plant={"load_inertia": 2e-4})

    motor = chain.motors[1]
    chain.execute("S.1=50, A.1=30, M.1=40, P.1=3000")
    chain.execute("^.1")
    chain.kernel.run(until=chain.kernel.now + seconds(0.01))
    axis = motor.axis
    args = (axis.profile, axis.motion.origin_ns, axis.motion.position_at(axis.motion.origin_ns),
            axis.motion.velocity_at(axis.motion.origin_ns), axis.motion.drive)
    memos = axis.memos                      # the chain's, shared by its motors
    reused_before, _ = memos.reuse()
    again = Motion(*args, memos)
    assert memos.reuse()[0] == reused_before + 1
    memos.clear()
    fresh = Motion(*args, memos)
    assert memos.reuse() == (0, 1)
    for a, b in zip(again.pieces, fresh.pieces, strict=True):
        assert (a.start, a.end, a.mode, a.pos, a.cmd, a.torque, a.err(), a.vel()) == \
               (b.start, b.end, b.mode, b.pos, b.cmd, b.torque, b.err(), b.vel())
    t = again.origin_ns + seconds(0.2)
    assert again.settled(5.0, t) == fresh.settled(5.0, t) is not None
    # the same move 1,000,000 pulses further on: the same errors, speeds and torques
    from coolmuscle.motor.motion.axis import _to_raw
    far = Motion(_to_raw(axis.profile, 1_000_000.0, 1), args[1], args[2] + 1_000_000,
                 args[3], args[4])
    assert len(far.pieces) == len(fresh.pieces)
    for a, b in zip(far.pieces, fresh.pieces):
        assert a.mode == b.mode and a.start == pytest.approx(b.start, abs=1e-9)
        assert a.pos[0] - 1_000_000 == pytest.approx(b.pos[0], abs=1e-6)
        assert xp.value(a.err(), a.k, 0.0) == pytest.approx(xp.value(b.err(), b.k, 0.0),
                                                          abs=1e-6)


# -- a command faster than the top speed --------------------------------------------------
# With K56 raised (ch. 3 K56) and S beyond the top speed, a move reversed while the shaft
# runs at full speed was braked through zero speed onto the command's speed with no
# top-speed exit: the shaft passed v_max and the modes after it chattered (sat -> track
# -> vmax, 1 ns each) until the 2000-piece safety net held the motor still.  The braking
# mode now ends at the top speed like the others.
FASTER_THAN_TOP_SPEED = ["K56.1=32767", "S.1=7027", "A.1=7698", "P.1=1", "^.1",
                         "P.1+=-500000", "^.1", "P.1+=-1", "^.1"]


@pytest.mark.parametrize("gap_ms", [50, 200, 1000])
def test_the_fuzzed_sequence_stays_far_below_the_piece_limit(
        gap_ms: int, caplog: pytest.LogCaptureFixture) -> None:
    counts: list[int] = []
    chain = Chain(motors=2)
    for motor in chain.motors.values():          # every motion each axis solves
        axis = motor.axis
        axis.trajectory_listeners.append(
            lambda axis=axis: counts.append(len(axis.motion.pieces)))
    with caplog.at_level(logging.WARNING):
        for line in FASTER_THAN_TOP_SPEED:
            chain.host_line.feed((line + "\r").encode())
            chain.kernel.run(until=chain.kernel.now + ms(gap_ms))
        chain.kernel.run(until=chain.kernel.now + ms(120_000))
    assert "piece limit" not in caplog.text
    assert counts and max(counts) < 100, max(counts)
    axis_speed = max(abs(chain.motors[1].axis.motion.velocity_at(chain.kernel.now - ms(t)))
                     for t in range(0, 100, 10))
    assert axis_speed == 0.0                           # standing (the K56 alarm or arrived)


def test_2_1_1_a_peak_torque_changed_while_pushing_a_stopper_applies_at_once(
        make_chain: ChainFactory) -> None:
    """M=100 is the maximum motor torque (2.1.1 "M"): against a stopper Ix shows the
    plant's peak torque, and a new peak torque at once (the plant is the motor's)."""
    chain, motor = _toward_a_stopper(make_chain)
    chain.kernel.run(until=seconds(1.0))
    assert chain.execute("?98.1") == ["Ix.1=300"]
    motor.plant.peak_torque = 200.0
    chain.kernel.run(until=seconds(1.1))
    assert chain.execute("?98.1") == ["Ix.1=200"]


def test_6_6_ix_of_an_extra_load_stays_its_share_of_a_changed_rated_torque(
        make_chain: ChainFactory) -> None:
    """An extra load of 50 % of rated (fault injection) holds Ix at 50 (6.6 ?98, % of
    rated); with a doubled rated torque the load is 50 % of the new rating."""
    chain = make_chain()
    motor = chain.motors[1]
    motor.faults.inject("overload", torque=50.0)
    chain.kernel.run(until=seconds(0.5))
    assert chain.execute("?98.1") in (["Ix.1=50"], ["Ix.1=-50"])
    motor.plant.rated_torque = 0.64
    chain.kernel.run(until=seconds(1.0))
    assert chain.execute("?98.1") in (["Ix.1=50"], ["Ix.1=-50"])
    assert motor.axis.motion.drive.a_load * motor.plant.nm_per_accel(
        motor.resolution.pulses_per_rev) == pytest.approx(0.32)


def test_ch3_k37_a_new_resolution_scales_the_servos_acceleration_units(
        make_chain: ChainFactory) -> None:
    """K37 (ch. 3, its table: pulses per revolution) sets the unit the servo model
    counts in: the torque limit as an acceleration doubles, in pulses/s², with twice
    the pulses per revolution, from the next motion on."""
    chain = make_chain()
    motor = chain.motors[1]
    assert motor.resolution.pulses_per_rev == 1000                 # K37=3, the default
    before = motor.axis.motion.drive.a_limit
    chain.execute("K37.1=4")                                       # 2000 pulses/rev
    chain.execute("S.1=10, A.1=10, P.1=1000")
    chain.execute("^.1")
    assert motor.axis.motion.drive.a_limit == pytest.approx(2.0 * before)
