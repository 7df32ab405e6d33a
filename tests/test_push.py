"""4.1.4 push motion with ``Q``/``Z`` given directly (2.2.2 "Q", "Z"; ch. 3 K60, K61).

Ux=32 while pushing (6.6 ?99) and the K34 function 9 output, 40 when the push has held
K60 for K61 ms, 256 when the target is reached with nothing to push (not with an odd
K60), endless with K61=0; ``motion_done()`` and the motion listeners are what a program
bank waits on.  The object pushed is a stopper of the machine file.
"""

from __future__ import annotations

import pytest

from coolmuscle.chain.machine import parse_machine
from coolmuscle.sim.kernel import NS_PER_S, seconds
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory, collect_events

OBJECT_AT = "[[axis]]\n[axis.stoppers]\ncw = 5000\n"


#: Output 1 is "in push motion" (K34 function 9); the push goes to P1, at S 20.
PUSH = "K34.1=9, P1.1=8000, S.1=20, A.1=100"


@pytest.mark.parametrize("command", ["Q1.1", "Z1.1"])
def test_4_1_4_push_holds_k60_for_k61_ms_then_ux_40(command: str, make_chain: ChainFactory) -> None:
    chain = make_chain(machine=parse_machine(OBJECT_AT), setup=PUSH)
    events = collect_events(chain, ["status", "alarm"])
    chain.execute("K60.1=50, K61.1=500")
    motor = chain.motors[1]
    chain.execute(command)
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?99.1") == ["Ux.1=32"]
    assert chain.execute("?51.1") == ["OUT1.1=1"]
    contact = 5000 / 2000 + 0.02 / 2 + 1 / 300 - 0.0      # 2000 pps, shaft lag 1/kp
    chain.kernel.run(until=seconds(2.8))
    assert motor.position() == 5000
    assert chain.execute("?98.1") == ["Ix.1=50"]            # pushing at K60
    assert not motor.motion_done()
    chain.kernel.run(until=seconds(5))
    (held,) = events
    assert held.text == "Ux.1=40" and abs(held.time / NS_PER_S - (contact + 0.5)) < 2e-3
    assert chain.execute("?99.1") == ["Ux.1=40"]
    assert chain.execute("?51.1") == ["OUT1.1=0"]
    assert chain.execute("?98.1") == ["Ix.1=0"]             # it holds, no longer pushes
    assert motor.motion_done()


def test_4_1_4_nothing_to_push_is_ux_256(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=PUSH)
    events = collect_events(chain, ["status", "alarm"])
    done: list[str] = []
    chain.motors[1].add_motion_listener(done.append)
    chain.execute("K34.1=92")                     # output 1: alarm, output 2: push
    chain.execute("Q1.1")
    chain.kernel.run(until=seconds(6))
    assert [e.text for e in events] == ["Ux.1=256"]
    assert done == ["push-error"]
    assert chain.execute("?99.1") == ["Ux.1=256"]
    assert chain.execute("?51.1") == ["OUT1.1=1"] and chain.execute("?52.1") == ["OUT2.1=0"]
    assert chain.execute("?96.1") == ["Px.1=8000"]
    chain.motors[1].reset_alarm()                           # input function 1
    assert chain.execute("?99.1") == ["Ux.1=8"]
    assert chain.execute("?51.1") == ["OUT1.1=0"]


def test_ch3_k60_odd_no_push_error(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=PUSH)
    events = collect_events(chain, ["status", "alarm"])
    chain.execute("K60.1=31")
    chain.execute("Q1.1")
    chain.kernel.run(until=seconds(6))
    assert [e.text for e in events] == ["Ux.1=8"]


def test_ch3_k61_zero_pushes_without_end(make_chain: ChainFactory) -> None:
    chain = make_chain(machine=parse_machine(OBJECT_AT), setup=PUSH)
    events = collect_events(chain, ["status", "alarm"])
    chain.execute("K61.1=0")
    chain.execute("Q1.1")
    chain.kernel.run(until=seconds(60))
    assert events == [] and chain.execute("?99.1") == ["Ux.1=32"]
    assert chain.execute("?98.1") == ["Ix.1=30"]            # K60 default
    chain.execute("]1.1")                         # a stop ends it where the shaft is
    chain.kernel.run(until=seconds(61))
    assert [(e.time, e.text) for e in events] == [(seconds(60), "Ux.1=8")]
    assert chain.execute("?99.1") == ["Ux.1=8"] and chain.execute("?98.1") == ["Ix.1=0"]


def test_push_is_not_a_position_error_overflow(make_chain: ChainFactory) -> None:
    chain = make_chain(machine=parse_machine(OBJECT_AT), setup=PUSH)
    events = collect_events(chain, ["status", "alarm"])
    chain.execute("K56.1=1, K61.1=2000")                    # 100 pulses; Pe reaches 3000
    chain.execute("Q1.1")
    chain.kernel.run(until=seconds(6))
    assert [e.text for e in events] == ["Ux.1=40"]


def test_4_1_4_push_begins_at_the_passing_point(make_chain: ChainFactory) -> None:
    # 4.1.4's line "S3.1, A1.1, P1.1, S1.1, Q2.1": "changes the speed to S1 at P1 and
    # start performing Push Motion toward P2": a plain move (Ux=0, torque limit M) up to
    # P1, the push (Ux=32, torque K60, K34 function 9) from P1 on
    chain = make_chain(machine=parse_machine(OBJECT_AT), setup=PUSH)
    events = collect_events(chain, ["status", "alarm"])
    motor = chain.motors[1]
    chain.execute("K34.1=9")
    fast = motor.limits(30, 100)
    slow = motor.limits(10, 100)
    motor.push_to(8000.0, slow, via=[(2000.0, fast)])
    chain.kernel.run(until=seconds(0.5))
    assert motor.speed_units() == 30 and chain.execute("?99.1") == ["Ux.1=0"]
    assert chain.execute("?51.1") == ["OUT1.1=0"]
    chain.kernel.run(until=seconds(1.5))
    assert motor.speed_units() == 10 and chain.execute("?99.1") == ["Ux.1=32"]
    assert chain.execute("?51.1") == ["OUT1.1=1"]
    chain.kernel.run(until=seconds(6))
    assert [e.text for e in events] == ["Ux.1=40"]


def test_cm1_push_level_is_k60_of_80_percent_of_full_torque(make_chain: ChainFactory) -> None:
    # cm1-ethernetip-interface-manual.txt Appendix A K60: "pushmode % is based on 80% of
    # full torque"; K61 = 30001 is the endless push
    chain = make_chain(firmware="cm1", machine=parse_machine(OBJECT_AT))
    chain.execute("K60.1=25, K61.1=30001, P1.1=8000, S.1=20, A.1=100")
    chain.execute("Q1.1")
    chain.kernel.run(until=seconds(60))
    assert chain.execute("?99.1") == ["Ux.1=32"]
    assert chain.execute("?98.1") == ["Ix.1=60"]            # 25 % x 80 % x 300 %
    assert chain.execute("?95.1") == ["Pe.1=3000"]          # a stepper pressed, not moving


def test_rt3_push_as_cm2(make_chain: ChainFactory) -> None:
    chain = make_chain(firmware="rt3", machine=parse_machine(OBJECT_AT))
    events = collect_events(chain, ["status"])
    chain.execute("P1.1=8000, S.1=20, A.1=100")
    chain.execute("Q1.1")
    chain.kernel.run(until=seconds(5))
    assert [e.text for e in events] == ["Ux.1=40"]


def test_4_1_4_trace_torque_clamped_at_k60_status_32_then_40(make_chain: ChainFactory) -> None:
    chain = make_chain(machine=parse_machine(OBJECT_AT), setup=PUSH)
    recorder = record(chain)
    chain.execute("K60.1=40, K61.1=300")
    chain.execute("Q1.1")
    chain.kernel.run(until=seconds(4))
    samples = [recorder.sample(1, t) for t in recorder.times(0.001)]
    assert max(abs(s.torque) for s in samples) <= 40.0 + 1e-9
    assert max(s.position for s in samples) <= 5000.0 + 1e-6
    statuses = [s.status for s in samples]
    first40 = statuses.index(40)
    assert set(statuses[:first40]) == {32} and set(statuses[first40:]) == {40}
    touching = [s.time for s in samples if s.status == 32 and abs(s.torque) > 39.999]
    assert abs((samples[first40].time - touching[0]) / NS_PER_S - 0.3) < 0.002
    assert all(s.outputs & 1 for s in samples[:first40])      # K34=9 while pushing
