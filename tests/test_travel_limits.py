"""Software limits K58/K59 (unit: K45 third digit) and the CW/CCW limit sensors (K27
functions 6 and 9; K23 messages ``error07.n: CW Limit!!`` / ``error08.n: CCW Limit!!``).

cml-users-guide.txt ch. 3 K23, K27, K45, K58, K59; docs/fidelity.md "Motion".
"""

from __future__ import annotations

import pytest

from coolmuscle.chain.machine import parse_machine
from coolmuscle.sim.kernel import NS_PER_S, seconds
from fixtures import ChainFactory, collect_events

LIMITS = """
[[axis]]
params = { K27 = 960, K23 = 17 }
[axis.cw_limit]
input = 2
on = [3000, inf]
[axis.ccw_limit]
input = 3
on = [-inf, -2000]
"""


#: What a limit says: status reports and messages (K23 1 and 16).
SAID = ("status", "message", "alarm")


@pytest.mark.parametrize("k45, k58, k59, high, low", [
    (1, 25, -7, 2500, -700),            # third digit 0: 100 pulses
    (101, 250, -70, 2500, -700),        # 1: 10 pulses
    (201, 2500, -700, 2500, -700),      # 2: 1 pulse
    (201, 0, 0, 10000, -10000),         # 0: no limit
])
def test_ch3_k58_k59_software_limits_stop_the_motion_there(
        k45: int, k58: int, k59: int, high: int, low: int, make_chain: ChainFactory) -> None:
    chain = make_chain(setup="K23.1=17")
    events = collect_events(chain, SAID)
    chain.execute(f"K45.1={k45}, K58.1={k58}, K59.1={k59}, S.1=100, A.1=100, P.1=10000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(3))
    assert chain.execute("?96.1") == [f"Px.1={high}"]
    chain.execute("P.1=-10000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(6))
    assert chain.execute("?96.1") == [f"Px.1={low}"]
    assert [e.text for e in events] == ["Ux.1=8", "Ux.1=8"]     # no message: none exists


def test_software_limit_ends_continuous_rotation(make_chain: ChainFactory) -> None:
    chain = make_chain(setup="K23.1=17")
    events = collect_events(chain, SAID)
    chain.execute("K45.1=201, K58.1=4000, S.1=50, A.1=100, P.1=1000000000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(3))
    assert chain.execute("?96.1") == ["Px.1=4000"] and events[-1].text == "Ux.1=8"


def test_ch3_k23_cw_limit_sensor_stops_the_motion_with_error07(make_chain: ChainFactory) -> None:
    chain = make_chain(machine=parse_machine(LIMITS), setup="K23.1=17")
    events = collect_events(chain, SAID)
    chain.execute("S.1=100, A.1=100, P.1=10000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(2))
    assert [e.text for e in events] == ["error07.1: CW Limit!!", "Ux.1=8"]
    limit_at = events[0].time / NS_PER_S
    assert abs(limit_at - (3000 + 10000 / 300 + 500) / 10000) < 1e-3
    x = chain.motors[1].position()
    assert 3000 < x < 3040                                    # maximum deceleration
    chain.execute("P.1=5000")                                  # toward it: refused
    chain.execute("^.1")
    assert events[-1].text == "error07.1: CW Limit!!"
    chain.execute("P.1=0")                                     # away from it: moves
    chain.execute("^.1")
    chain.kernel.run(until=seconds(4))
    assert chain.execute("?96.1") == ["Px.1=0"]


def test_ch3_k23_ccw_limit_sensor_error08_and_the_device_api(make_chain: ChainFactory) -> None:
    chain = make_chain(machine=parse_machine(LIMITS), setup="K23.1=17")
    events = collect_events(chain, SAID)
    chain.execute("S.1=100, A.1=100, P.1=-10000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(2))
    assert [e.text for e in events] == ["error08.1: CCW Limit!!", "Ux.1=8"]
    motor = chain.motors[1]
    motor.limit_sensor(-1, True)                               # idempotent
    assert len(events) == 2
    chain.execute("S.1=-10, P.1=1000000000")                   # CCW rotation refused
    chain.execute("^.1")
    assert events[-1].text == "error08.1: CCW Limit!!"


@pytest.mark.parametrize("target, direction, wait", [
    (595, 1, 1.0), (595, 1, 3.0), (-595, -1, 1.0), (-595, -1, 3.0), (-100, -1, 1.5)])
def test_ch3_k27_a_limit_sensor_coming_on_at_rest_is_no_error(
        target: int, direction: int, wait: float, make_chain: ChainFactory) -> None:
    """A sensor that comes on after the move ended (Ux=8, Sx=0, Pe=0) stops nothing and
    reports nothing, however long ago the move ended: only a motion toward it does
    (ch. 3 K23 error07/08).  The servo's settling tail (a fraction of a pulse a second)
    once counted as moving toward it, up to a few seconds after the move (an audit of
    the manual's examples found it)."""
    chain = make_chain(machine=parse_machine("[[axis]]\nparams = { K27 = 96, K23 = 17 }\n"),
                       setup="K23.1=17")
    events = collect_events(chain, SAID)
    chain.execute("S.1=10, A.1=100")
    chain.execute(f"P.1={target}")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(wait))
    assert [e.text for e in events] == ["Ux.1=8"]
    assert chain.execute("?97.1") == ["Sx.1=0"] and chain.execute("?95.1") == ["Pe.1=0"]
    chain.motors[1].limit_sensor(direction, True)
    chain.kernel.run(until=seconds(wait + 0.5))
    assert [e.text for e in events] == ["Ux.1=8"]
    chain.execute(f"P.1={target + 1000 * direction}")          # toward it: refused
    chain.execute("^.1")
    assert events[-1].text == ("error07.1: CW Limit!!" if direction > 0
                             else "error08.1: CCW Limit!!")


def test_limit_messages_need_k23_16(make_chain: ChainFactory) -> None:
    chain = make_chain(machine=parse_machine(LIMITS), setup="K23.1=17")
    events = collect_events(chain, SAID)
    chain.execute("K23.1=1, S.1=100, A.1=100, P.1=10000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(2))
    assert [e.text for e in events] == ["Ux.1=8"]
