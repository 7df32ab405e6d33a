"""Manual jog and feed (cml-users-guide.txt 5.1; ch. 3 K43, K49, K50, table 6.1 K50).

The input functions (K27-K32) call ``Motor.jog`` / ``feed`` / ``feed_stop``; these
tests call them directly and read what the motor reports and the trace.
"""

from __future__ import annotations

import pytest

from coolmuscle.device.api import Event
from coolmuscle.sim.kernel import seconds
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory, collect_events


def _status_times(events: list[Event]) -> list[tuple[float, str]]:
    return [(e.time / 1e9, e.text) for e in events if e.kind == "status"]


def test_5_1_jog_moves_k50_pulses_each_one_shot(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    events = collect_events(chain)
    motor = chain.motors[1]
    chain.set_param(1, 50, 10)
    motor.jog(1)
    chain.kernel.run(until=seconds(0.5))
    assert chain.execute("?96.1") == ["Px.1=10"]
    motor.jog(1)
    chain.kernel.run(until=seconds(1.0))
    motor.jog(-1)
    chain.kernel.run(until=seconds(1.5))
    assert chain.execute("?96.1") == ["Px.1=10"]
    chain.set_param(1, 50, 100)
    motor.jog(-1)
    chain.kernel.run(until=seconds(2.0))
    assert chain.execute("?96.1") == ["Px.1=-90"]
    assert [text for _, text in _status_times(events)] == ["Ux.1=8"] * 4


def test_table_6_1_k50_jog_speed_and_acceleration_are_automatic(make_chain: ChainFactory) -> None:
    """K50: "Speed and acceleration are set automatically and can not be changed":
    S, A, K49, K43, K51 and K69 make no difference to a jog."""
    timings = []
    for s, a, k49, k43, k51, k69 in ((100, 100, 10, 100, 0, 0), (5, 3, 900, 7, 3, 1024)):
        chain = make_chain(traced=True)
        events = collect_events(chain)
        chain.execute(f"S.1={s}, A.1={a}")
        for k, v in ((49, k49), (43, k43), (51, k51), (69, k69), (50, 100)):
            chain.set_param(1, k, v)
        chain.motors[1].jog(1)
        chain.kernel.run(until=seconds(1))
        timings.append(_status_times(events))
    assert timings[0] == timings[1]
    # 100 pulses at 1 rev/s (1000 pps at K37=3), 100 kpps²: 10 ms up, 90 ms, 10 ms down;
    # in position (K55 = 5) once within 5 pulses of 100, a few ms before the command ends
    assert 0.1 < timings[0][0][0] < 0.11


def test_5_1_jog_while_moving_is_ignored(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    chain.execute("S.1=10, A.1=100, P.1=1000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(0.2))
    motor.jog(1)
    chain.kernel.run(until=seconds(3))
    assert chain.execute("?96.1") == ["Px.1=1000"]


def test_5_1_jog_cw_is_the_physical_direction_under_reverse_coordinates(
        make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    motor.axis.sign = -1          # K45 first digit 2/3 (the origin search owns setting it)
    motor.jog(1)
    chain.kernel.run(until=seconds(0.5))
    assert chain.execute("?96.1") == ["Px.1=-10"]
    assert motor.axis.raw_actual() == pytest.approx(10, abs=0.01)


def test_5_1_feed_runs_at_k49_with_k43_while_the_signal_is_on(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    events = collect_events(chain)
    motor = chain.motors[1]
    chain.set_param(1, 49, 20)            # 2000 pps at K37=3
    chain.set_param(1, 43, 50)            # 50 kpps²: 40 ms to full speed
    chain.set_param(1, 44, 200)           # stop at 100 kpps²: 20 ms
    motor.feed(1)
    rec = record(chain)
    assert rec.sample(1, seconds(0.02)).command == pytest.approx(10.0)    # ½·a·t²
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?97.1") == ["Sx.1=20"]
    assert not _status_times(events)
    motor.feed_stop()
    chain.kernel.run(until=seconds(2))
    # 20 ms ramp (20 pulses) + 1 s cruise... stop: 2000²/(2·100000) = 20 pulses
    assert motor.axis.target() == pytest.approx(40 + 1920 + 20, abs=1e-6)
    (stopped, _), = _status_times(events)    # within K55 of the stop point (1.02 s)
    assert 1.01 < stopped < 1.02
    motor.feed(-1)
    chain.kernel.run(until=seconds(3))
    assert chain.execute("?97.1") == ["Sx.1=-20"]


@pytest.mark.parametrize("interrupt", ["alarm", "pause", "estop"])
def test_5_1_feed_stopped_by_alarm_or_stop_needs_signal_off_then_on(
        interrupt: str, make_chain: ChainFactory) -> None:
    """5.1: "If a motion is stopped by an alarm or stop command ... cancel an alarm then
    turn signal off then back on"."""
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    motor.feed(1)
    chain.kernel.run(until=seconds(0.5))
    if interrupt == "alarm":
        motor.raise_alarm(4)
        motor.reset_alarm()
    elif interrupt == "pause":
        chain.execute("].1")
    else:
        chain.execute("*.1")
        chain.execute("*1.1")
    chain.kernel.run(until=seconds(1))
    motor.feed(1)                     # the signal is still on: nothing happens
    chain.kernel.run(until=seconds(1.5))
    assert chain.execute("?97.1") == ["Sx.1=0"]
    motor.feed_stop()                 # off ...
    motor.feed(1)                     # ... and on again
    chain.kernel.run(until=seconds(2))
    assert chain.execute("?97.1") == ["Sx.1=10"]


def test_5_1_feed_while_another_motion_runs_waits_for_the_signal_to_go_off(
        make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    chain.execute("S.1=10, A.1=100, P.1=500")
    chain.execute("^.1")
    motor.feed(1)
    chain.kernel.run(until=seconds(2))
    assert chain.execute("?96.1") == ["Px.1=500"]
    motor.feed(1)
    assert chain.execute("?97.1") == ["Sx.1=0"]
    motor.feed_stop()
    motor.feed(-1)
    chain.kernel.run(until=seconds(3))
    assert chain.execute("?97.1") == ["Sx.1=-10"]


def test_5_1_motor_free_refuses_jog_and_feed(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    chain.execute(").1")
    motor.jog(1)
    motor.feed(1)
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?96.1") == ["Px.1=0"]
