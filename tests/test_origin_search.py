"""5.3 origin search: every K46 source, each K45 direction (with reverse coordinates),
with and without the origin signal on at the start, limit-sensor reversal, the K48 offset,
automatic search at power-up, and the replies ``Origin.n=<phase>`` then ``Ux.n=8``.

cml-users-guide.txt 5.3, 5.3.1-5.3.3; ch. 3 K27, K34 (function 4), K42-K48.  The machine
(stoppers, sensors, Z phase) comes from machine-file text (docs/machine-file.md).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.chain.machine import parse_machine
from coolmuscle.sim.kernel import seconds
from fixtures import ChainFactory


def _search(machine: str, params: str, *, start: bool = True,
            until: float = 30.0) -> tuple[Chain, list[str]]:
    chain = Chain(machine=parse_machine("[[axis]]\nmotor = 1\n" + machine))
    events: list[str] = []
    chain.subscribe(lambda ev: events.append(ev.text) if ev.kind in (
        "status", "origin", "alarm", "message") else None)
    chain.execute(params)
    if start:
        chain.execute("|.1")
    chain.kernel.run(until=seconds(until))
    return chain, events


CW, CCW = 1, -1

#: (K46, machine text, expected raw origin and reported phase) per search direction.
CASES = {
    # 5.3.1 stopper: contact at ±3017, phase 17/20 = 850 (CW) or 3/20 = 150 (CCW),
    # back off to the phase-0 point away from the stopper
    (0, CW): ("[axis.stoppers]\ncw = 3017\n", 3000.0, 850),
    (0, CCW): ("[axis.stoppers]\nccw = -3017\n", -3000.0, 150),
    # 5.3.2 sensor: the rising edge met moving toward K45
    (2, CW): ("[axis.origin_sensor]\ninput = 1\non = [2000, 2400]\n", 2000.0, 0),
    (2, CCW): ("[axis.origin_sensor]\ninput = 1\non = [-2413, -2010]\n", -2010.0, 500),
    # 5.3.3 Z phase once a revolution (window 1/50 turn from z_phase)
    (4, CW): ("[axis.drive]\nz_phase = 250\n", 250.0, 0),
    (4, CCW): ("[axis.drive]\nz_phase = 250\n", -730.0, 0),
    # 5.3.3 origin sensor AND Z phase
    (6, CW): ("[axis.drive]\nz_phase = 250\n[axis.origin_sensor]\ninput = 1\n"
              "on = [2000, 2600]\n", 2250.0, 0),
    (6, CCW): ("[axis.drive]\nz_phase = 250\n[axis.origin_sensor]\ninput = 1\n"
               "on = [-2900, -2100]\n", -2730.0, 0),
}


@pytest.mark.parametrize("reverse", [False, True], ids=["normal", "reverse-coordinates"])
@pytest.mark.parametrize("k46, direction", list(CASES), ids=[
    f"K46={k}-{'CW' if d > 0 else 'CCW'}" for k, d in CASES])
def test_5_3_origin_search(k46: int, direction: int, reverse: bool) -> None:
    machine, origin, phase = CASES[(k46, direction)]
    k45 = (0 if direction == CW else 1) + (2 if reverse else 0)
    chain, events = _search(machine, f"K27.1=2, K46.1={k46}, K45.1={k45}, K34.1=4")
    motor = chain.motors[1]
    assert events == [f"Origin.1={phase}", "Ux.1=8"]
    assert motor.origin_done and chain.execute("?51.1") == ["OUT1.1=1"]
    assert abs(motor.axis.raw_actual() - origin) < 1e-3
    assert chain.execute("?96.1") == ["Px.1=0"]
    chain.execute("S.1=10, P.1=10")
    chain.execute("^.1")
    assert chain.execute("?51.1") == ["OUT1.1=0"]           # in position only
    chain.kernel.run(until=seconds(40))
    expected = origin + (-10 if reverse else 10)              # reverse: user + is CCW
    assert abs(motor.axis.raw_actual() - expected) < 1e-3
    assert chain.execute("?51.1") == ["OUT1.1=1"]


@pytest.mark.parametrize("k46, direction, machine, origin", [
    # sensor made at the start: leave it the other way, then come back to its edge
    (2, CW, "[axis.origin_sensor]\ninput = 1\non = [-300, 500]\n", -300.0),
    (2, CCW, "[axis.origin_sensor]\ninput = 1\non = [-300, 500]\n", 500.0),
    (4, CW, "[axis.drive]\nz_phase = -10\n", -10.0),
    (4, CCW, "[axis.drive]\nz_phase = -10\n", 10.0),
    (6, CW, "[axis.drive]\nz_phase = -10\n[axis.origin_sensor]\ninput = 1\non = [-50, 50]\n",
     -10.0),
])
def test_5_3_2_signal_on_at_the_start(k46: int, direction: int, machine: str,
                                      origin: float) -> None:
    chain, events = _search(machine, f"K27.1=2, K46.1={k46}, K45.1={0 if direction > 0 else 1}")
    assert events[-1] == "Ux.1=8" and events[0].startswith("Origin.1=")
    assert abs(chain.motors[1].axis.raw_actual() - origin) < 1e-3


def test_5_3_2_limit_sensor_reverses_at_double_speed(make_chain: ChainFactory) -> None:
    machine = ("[axis.origin_sensor]\ninput = 1\non = [-1500, -1000]\n"
               "[axis.cw_limit]\ninput = 2\non = [2000, inf]\n")
    chain = make_chain(machine=parse_machine("[[axis]]\n" + machine))
    chain.execute("K27.1=62, K46.1=2, K45.1=0, K42.1=10")
    speeds: list[float] = []
    chain.execute("|.1")
    motor = chain.motors[1]
    for t in range(1, 60):
        chain.kernel.run(until=seconds(t * 0.1))
        speeds.append(motor.axis.velocity())
    assert max(speeds) == pytest.approx(1000.0, rel=1e-3)     # K42 = 10 x 100 pps
    assert min(speeds) == pytest.approx(-2000.0, rel=1e-3)    # back at double speed
    chain.kernel.run(until=seconds(20))
    assert abs(motor.axis.raw_actual() + 1500.0) < 1e-3       # its CCW-side edge
    assert motor.origin_done


def test_5_3_2_limit_sensor_is_the_origin_sensor_without_one() -> None:
    # K27 6: "works as an origin sensor for the origin search motion to CW direction"
    chain, events = _search("[axis.cw_limit]\ninput = 2\non = [1200, inf]\n",
                            "K27.1=60, K46.1=2, K45.1=0")
    assert events == ["Origin.1=0", "Ux.1=8"]
    assert abs(chain.motors[1].axis.raw_actual() - 1200.0) < 1e-3


@pytest.mark.parametrize("k45, k48, offset", [(1, 3, 300), (11, 3, 30), (21, 150, 150),
                                              (23, 150, -150)])
def test_ch3_k48_offset_in_k45_units(k45: int, k48: int, offset: float) -> None:
    chain, events = _search("[axis.origin_sensor]\ninput = 1\non = [-2413, -2010]\n",
                            f"K27.1=2, K46.1=2, K45.1={k45}, K48.1={k48}")
    assert events == ["Origin.1=500", "Ux.1=8"]
    assert abs(chain.motors[1].axis.raw_actual() - (-2010.0 + offset)) < 1e-3
    assert chain.execute("?96.1") == ["Px.1=0"]


def test_ch3_k46_odd_searches_at_power_up(make_chain: ChainFactory) -> None:
    text = "[[axis]]\nparams = { K46 = 1 }\n[axis.stoppers]\nccw = -1234\n"
    chain = make_chain(machine=parse_machine(text))
    events: list[str] = []
    chain.subscribe(lambda ev: events.append(ev.text))
    chain.kernel.run(until=seconds(10))
    assert events == ["Origin.1=300", "Ux.1=8"]
    assert abs(chain.motors[1].axis.raw_actual() + 1220.0) < 1e-3


def test_5_3_1_stopper_needs_the_speed_below_a_sixteenth_of_k42() -> None:
    # a heavy load at a high K43: the start torque passes K47 while still slow ->
    # the search stops there (the manual's warning under K47)
    chain, events = _search("[axis.load]\ninertia = 5e-4\n[axis.stoppers]\nccw = -5000\n",
                            "K43.1=2000, K47.1=30")
    assert events[-1] == "Ux.1=8"
    assert chain.motors[1].axis.raw_actual() > -100          # detected at the start
    chain, events = _search("[axis.load]\ninertia = 5e-4\n[axis.stoppers]\nccw = -5000\n",
                            "K43.1=20, K47.1=30")
    assert abs(chain.motors[1].axis.raw_actual() + 5000.0) < 1e-3


def test_a_stop_abandons_the_search() -> None:
    chain, events = _search("[axis.stoppers]\nccw = -5000\n", "K46.1=0", until=1.0)
    chain.execute("]1.1")
    chain.kernel.run(until=seconds(10))
    assert events == ["Ux.1=8"] and not chain.motors[1].origin_done


def test_ch3_k45_saved_reverse_coordinates_apply_at_power_up(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain(state_dir=tmp_path)
    chain.execute("K45.1=3")
    chain.close()
    chain = make_chain(state_dir=tmp_path)
    chain.execute("S.1=10, P.1=100")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?96.1") == ["Px.1=100"]
    assert abs(chain.motors[1].axis.raw_actual() + 100.0) < 1e-3   # CCW is positive
    chain.close()


@pytest.mark.parametrize("firmware, k46, k48, origin", [("cm1", 16, 2, -3000.0 + 200),
                                                        ("rt3", 0, 2, -3000.0 + 2)])
def test_other_firmware_stopper_search(firmware: str, k46: int, k48: int,
                                       origin: float) -> None:
    # CM1: K46 16 = stopper without power-up search, K48 in 100 pulses; RT3 as CM2
    chain = Chain(firmware=firmware, machine=parse_machine(
        "[[axis]]\n[axis.stoppers]\nccw = -3017\n"))
    events: list[str] = []
    chain.subscribe(lambda ev: events.append(ev.text) if ev.kind in ("status", "origin")
                    else None)
    chain.execute(f"K46.1={k46}, K45.1=1, K48.1={k48}" if firmware == "cm1"
                  else f"K46.1={k46}, K45.1=21, K48.1={k48}")
    chain.execute("|.1")
    chain.kernel.run(until=seconds(10))
    assert events == ["Origin.1=150", "Ux.1=8"]
    assert abs(chain.motors[1].axis.raw_actual() - origin) < 1e-3
