"""Alarms out of the servo and load model, and injected faults.

Each gives its Ux value (cml-users-guide.txt 6.6 ?99), its ``Ux.n=`` event (ch. 3 K23
function 1), the K34 alarm output (function 2), the motor going free, and its recovery by
``(`` (CM1 manual 3.2.3 ControlWord 3) or by the input function "alarm reset" (K28 = 1).
Thresholds: K56 (position error overflow), K57 (overload time), K40 (over speed),
the I²t model (temperature); docs/fidelity.md "Servo, load and alarms".
"""

from __future__ import annotations

import math

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.device.api import Event
from coolmuscle.sim.kernel import NS_PER_S, seconds
from fixtures import ChainFactory, collect_events

#: Output 1 is the alarm output (K34 function 2); reports and messages on (K23 17).
ALARM_OUTPUT = "K34.1=2, K23.1=17"


def _reports(events: list[Event]) -> list[tuple[float, str]]:
    return [(round(e.time / NS_PER_S, 6), e.text) for e in events
            if e.kind in ("status", "alarm", "message", "origin")]


def _free_and_recover(chain: Chain, ux: int, *, by_reset: bool = False) -> None:
    assert chain.execute("?99.1") == [f"Ux.1={ux}"]
    assert chain.execute("?51.1") == ["OUT1.1=1"]          # K34 function 2: alarm
    motor = chain.motors[1]
    assert not motor.axis.enabled and motor.torque() == 0
    if by_reset:
        motor.reset_alarm()
    else:
        chain.execute("(.1")
    assert chain.execute("?99.1") == ["Ux.1=8"]
    assert chain.execute("?51.1") == ["OUT1.1=0"]
    assert motor.axis.enabled


def test_ch3_k56_position_error_overflow_at_a_stopper(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.motors[1].geometry.stopper_cw = 2000.0
    chain.execute("K56.1=10, S.1=50, A.1=100, P.1=50000")   # 1000 pulses, 5000 pps
    chain.execute("^.1")
    chain.kernel.run(until=seconds(2))
    (when, text), = _reports(events)
    assert text == "Ux.1=1"
    assert events[-1].kind == "alarm"
    # the shaft meets the stopper at 2000 while the command is Pe = 16.7 pulses ahead;
    # the command runs on at 5000 pps until Pe passes 1000 pulses
    t_contact = 2000 / 5000 + 0.05 / 2 + 1 / 300
    assert math.isclose(when, t_contact + (1000 - 5000 / 300) / 5000, abs_tol=2e-3)
    _free_and_recover(chain, 1)


@pytest.mark.parametrize("k56, ux", [(1, 1), (2, 0)])
def test_ch3_k56_changed_during_a_move_applies_at_once(make_chain: ChainFactory, k56: int,
                                                       ux: int) -> None:
    """The lag of a move at 50 000 pps is about 167 pulses (speed / kp): K56=1 (100
    pulses) set during the move raises the overflow at once, K56=2 (200 pulses) does not
    (the watcher reads K56 again when a K value changes)."""
    chain = make_chain(1)
    chain.execute("K56.1=32767, S.1=500, A.1=1000, P.1=1000000, ^.1")
    chain.kernel.advance(seconds(0.2))
    assert chain.execute("?95.1") == ["Pe.1=167"] and chain.execute("?99.1") == ["Ux.1=0"]
    chain.execute(f"K56.1={k56}")
    chain.kernel.advance(seconds(0.001))
    assert chain.execute("?99.1") == [f"Ux.1={ux}"]


def test_ch3_k57_overload_after_k57_ms_beyond_rated_torque(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.motors[1].geometry.stopper_cw = 1000.0
    chain.execute("K57.1=500, S.1=10, A.1=100, P.1=1010")   # pushes 10 pulses past it
    chain.execute("^.1")
    chain.kernel.run(until=seconds(3))
    (when, text), = _reports(events)
    contact = 1000 / 1000 + 0.01 / 2 + 1 / 300   # creep-free trapezoid, lag of the loop
    assert text == "Ux.1=4"
    assert math.isclose(when, contact + 0.5, abs_tol=5e-3)
    _free_and_recover(chain, 4, by_reset=True)


def test_ch3_k40_over_speed_when_the_load_runs_away(make_chain: ChainFactory) -> None:
    # a hanging load of 200 % rated against a torque limit of 30 % (M=10): the shaft is
    # dragged down past 1.2 x K40 = 1200 min⁻¹ = 20 000 pps
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.execute("K40.1=1000, M.1=10")
    chain.inject_fault(1, "overload", torque=200)       # held by +torque: it pulls CCW
    motor = chain.motors[1]
    assert chain.kernel.run_until(lambda: bool(events), seconds(1))
    (when, text), = _reports(events)
    assert text == "Ux.1=2"
    assert motor.axis.velocity() == pytest.approx(-20000, rel=1e-6)
    chain.inject_fault(1, "overload", clear=True)
    chain.kernel.run(until=seconds(2))
    _free_and_recover(chain, 2)


def test_ch3_k40_an_s_above_the_maximum_speed_is_limited_to_it(make_chain: ChainFactory) -> None:
    # ch. 3 K40: "This parameter sets motor's maximum speed" and "S value = speed[min⁻¹]
    # x resolution[ppr] / speed unit / 60": K40=1000 at K37=3 is S 166.7; S=250 runs
    # at that speed, in position at the end, no position error overflow
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.execute("K40.1=1000, S.1=250, A.1=100, P.1=100000")  # 25 000 pps > 16 667
    chain.execute("^.1")
    chain.kernel.run(until=seconds(0.5))
    assert chain.motors[1].axis.velocity() == pytest.approx(1000 * 1000 / 60)
    assert chain.execute("?97.1") == ["Sx.1=167"]
    chain.kernel.run(until=seconds(8))
    assert [t for _, t in _reports(events)] == ["Ux.1=8"]
    assert chain.execute("?96.1") == ["Px.1=100000"]


def test_ch3_k40_issue_example_k40_600_s200_runs_at_s100(make_chain: ChainFactory) -> None:
    # the issue's case: K40=600 -> max S = 600 x 1000 / 100 / 60 = 100
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.execute("K40.1=600, S.1=200, A.1=100, P.1=50000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?97.1") == ["Sx.1=100"]
    chain.kernel.run(until=seconds(7))
    assert [t for _, t in _reports(events)] == ["Ux.1=8"]
    assert chain.execute("?99.1") == ["Ux.1=8"]


def test_ch3_k40_limits_continuous_rotation_too(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    chain.execute("K40.1=600, S.1=-200, A.1=100, P.1=1000000000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?97.1") == ["Sx.1=-100"]
    assert chain.execute("?99.1") == ["Ux.1=0"]


def test_6_6_temperature_rises_and_cools_in_closed_form_then_alarms(
        make_chain: ChainFactory) -> None:
    chain = make_chain(plant={"load_torque": 0.9 * 0.32},      # a vertical axis: 90 % held
                       setup=ALARM_OUTPUT)
    events = collect_events(chain)
    motor = chain.motors[1]
    motor.thermal.idle, motor.thermal.time_constant = 60.0, 10.0
    motor.thermal.reset(None, chain.kernel.now)
    motor.axis.refresh()
    steady = 60.0 + 40.0 * 0.81
    chain.kernel.run(until=seconds(10))
    assert chain.execute("?71.1") == [f"Temp.1={round(steady - (steady - 60) / math.e)}"]
    chain.kernel.run(until=seconds(15))
    (when, text), = _reports(events)
    assert text == "Ux.1=128"
    assert math.isclose(when, 10.0 * math.log((steady - 60) / (steady - 85)), abs_tol=1e-3)
    # free: no torque, it cools toward the idle temperature
    chain.kernel.run(until=seconds(when + 10))
    assert chain.execute("?71.1") == [f"Temp.1={round(60 + 25 / math.e)}"]
    _free_and_recover(chain, 128)


def test_temperature_alarm_returns_when_reset_while_hot(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.inject_fault(1, "over_temperature", temperature=95)
    assert _reports(events) == [(0.0, "Ux.1=128")]
    assert chain.execute("?71.1") == ["Temp.1=95"]
    chain.execute("(.1")
    chain.kernel.run(until=seconds(0.001))
    assert chain.execute("?99.1") == ["Ux.1=128"]            # still too hot
    chain.kernel.run(until=seconds(600))
    chain.execute("(.1")
    assert chain.execute("?99.1") == ["Ux.1=8"]


@pytest.mark.parametrize("fault, ux", [("over_current", 64), ("regeneration", 2),
                                       ("over_speed", 2), ("encoder", 1)])
def test_injected_alarm_faults(fault: str, ux: int, make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.execute("S.1=100, A.1=100, P.1=10000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(0.3))
    chain.inject_fault(1, fault)
    assert _reports(events) == [(0.3, f"Ux.1={ux}")]
    x = chain.motors[1].axis.position()
    chain.kernel.run(until=seconds(1))
    assert chain.motors[1].axis.position() > x              # coasting, free
    _free_and_recover(chain, ux)


def test_a_second_alarm_adds_its_code(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.inject_fault(1, "over_current")
    chain.inject_fault(1, "over_temperature")
    assert [t for _, t in _reports(events)] == ["Ux.1=64", "Ux.1=192"]


def test_overload_fault_is_a_jam_the_motor_answers(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.execute("K57.1=200")
    chain.inject_fault(1, "overload", torque=150)
    assert chain.execute("?98.1") == ["Ix.1=150"]           # holding against it
    chain.kernel.run(until=seconds(1))
    assert [(e.time, e.text) for e in events if e.kind == "alarm"] == \
        [(seconds(0.2) + 1, "Ux.1=4")]                       # "more than" K57 ms
    chain.inject_fault(1, "overload", clear=True)
    _free_and_recover(chain, 4)


def test_power_cable_broken_no_torque_then_position_error(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.inject_fault(1, "broken_cable", cable="power")
    chain.execute("K56.1=5, S.1=10, A.1=100, P.1=2000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(2))
    assert chain.motors[1].position() == 0
    assert [t for _, t in _reports(events)] == ["Ux.1=1"]
    chain.inject_fault(1, "broken_cable", cable="power", clear=True)
    _free_and_recover(chain, 1)
    chain.execute("^.1")
    chain.kernel.run(until=seconds(6))
    assert chain.execute("?96.1") == ["Px.1=2000"]


def test_supply_voltage_drop_shows_in_vsen_and_limits_speed(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    chain.inject_fault(1, "supply_voltage", volts=12.0)
    assert chain.execute("?72.1") == ["VSEN.1=120"]
    chain.execute("K40.1=4000, K56.1=32767, S.1=500, A.1=1000, P.1=1000000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(1))
    assert chain.motors[1].axis.velocity() == pytest.approx(4500 / 2 * 1000 / 60)
    chain.inject_fault(1, "supply_voltage", clear=True)
    assert chain.execute("?72.1") == ["VSEN.1=240"]


def test_stuck_input_and_broken_io_cable(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    events = collect_events(chain)
    chain.execute("K23.1=19")
    chain.inject_fault(1, "stuck_input", input=3, on=True)
    chain.set_input(1, 3, False)
    assert chain.execute("?70.1") == ["IN.1=04"]
    chain.set_input(1, 1, True)
    chain.inject_fault(1, "broken_cable", cable="io")
    assert chain.execute("?70.1") == ["IN.1=04"]            # the stuck one is stuck
    chain.inject_fault(1, "stuck_input", input=3, clear=True)
    assert chain.execute("?70.1") == ["IN.1=00"]
    chain.inject_fault(1, "broken_cable", cable="io", clear=True)
    assert chain.execute("?70.1") == ["IN.1=01"]            # input 1 is still driven on
    assert [e.text for e in events if e.kind == "input"] == \
        ["IN.1=04", "IN.1=05", "IN.1=04", "IN.1=00", "IN.1=01"]


def test_unknown_fault_or_parameter_is_refused(make_chain: ChainFactory) -> None:
    chain = make_chain(setup=ALARM_OUTPUT)
    with pytest.raises(ValueError, match="unknown fault"):
        chain.inject_fault(1, "gremlins")
    with pytest.raises(ValueError, match="no parameter"):
        chain.inject_fault(1, "over_current", amps=3)
    with pytest.raises(ValueError):
        chain.inject_fault(1, "stuck_input", input=9, on=True)
    assert chain.execute("?99.1") == ["Ux.1=8"]


@pytest.mark.parametrize("fault, params", [
    ("overload", {"torque": 1e308}), ("overload", {"torque": -1e6}),
    ("overload", {"torque": math.inf}), ("overload", {"torque": math.nan}),
    ("over_temperature", {"temperature": 1e308}),
    ("over_temperature", {"temperature": -300.0}),
    ("supply_voltage", {"volts": math.nan}), ("supply_voltage", {"volts": 1001}),
])
def test_a_fault_value_out_of_its_bounds_is_refused_and_the_motor_stays_sane(
        fault: str, params: dict[str, float], make_chain: ChainFactory) -> None:
    """An injected value beyond what it can mean (10x the rated torque, -40..200 °C,
    0..1000 V) or not finite is refused (ValueError: the web page's and the API's
    error answer) and changes nothing; once a 1e308 % overload turned every position
    into NaN for good (an attack on the web dashboard found it)."""
    chain = make_chain(setup=ALARM_OUTPUT)
    chain.execute("S.1=100, A.1=100, P.1=5000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(0.2))
    with pytest.raises(ValueError, match="must be"):
        chain.inject_fault(1, fault, **params)
    chain.kernel.run(until=seconds(2))
    assert chain.execute("?96.1") == ["Px.1=5000"]
    assert chain.execute("?99.1") == ["Ux.1=8"]
    temp = chain.execute("?71.1")[0]
    assert -40 <= float(temp.split("=")[1]) <= 200, temp
    chain.inject_fault(1, "overload", torque=1000)               # the bounds themselves
    chain.inject_fault(1, "over_temperature", temperature=-40)
    chain.kernel.run(until=seconds(4))
    assert all(math.isfinite(float(chain.execute(q)[0].split("=")[1]))
               for q in ("?96.1", "?95.1", "?97.1"))
