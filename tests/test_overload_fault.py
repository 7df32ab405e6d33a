"""The overload fault and the motor it frees: bounded, continuous motion in closed form.

cml-users-guide.txt ch. 3 K57: "Motor outputs overload alarm when the overload condition
continues more than 3000msec, and stops in motor free state"; 6.6 ?98 Ix, ?99 Ux=4,
?71.  docs/machine-file.md "Faults": the overload fault is an extra constant load
torque; docs/fidelity.md "Servo, load and alarms" has the model of a free shaft driven
by its load (it spins up to the back-EMF speed, rests on a stopper, makes no torque and
does not heat) and of the position counter (it wraps past the K37 maximum position).

Every expected value is worked out here from the plant's figures (the default 17-size
motor: rotor 0.45e-5 kg·m², rated 0.32 N·m, friction 0.004 N·m, 4500 min⁻¹), not read
back from the model.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import pytest

from cli_support import cli
from coolmuscle.chain.daisy import Chain
from coolmuscle.motor.motion.plant import Plant
from coolmuscle.sim.kernel import NS_PER_S, seconds
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory, collect_events

PLANT = Plant()
PER = PLANT.nm_per_accel(1000)                       # N·m per pulse/s² at 1000 ppr
#: The fault's 200 % of rated pulls CCW; the friction (0.004 N·m) holds against it.
A_NET = (2.0 * PLANT.rated_torque - PLANT.coulomb_friction) / PER
V_FREE = 4500 * 1000 / 60                            # 75 000 pps: the back-EMF speed
SPIN_UP = V_FREE / A_NET                             # s from the alarm to V_FREE
SPIN_UP_DISTANCE = V_FREE ** 2 / (2 * A_NET)         # pulses covered meanwhile
#: K57 = 3000 ms ("more than": 1 ns beyond it) after the fault at 1 s.
ALARM_NS = seconds(1) + 3000 * 1_000_000 + 1

MACHINE = """\
[[axis]]
motor = 1
[axis.stoppers]
ccw = -3000
cw = 3000
[[axis.fault]]
at = 1.0
fault = "overload"
torque = 200
"""


def free_position(after_alarm: float) -> float:
    """Where the freed shaft is (pulses) ``after_alarm`` seconds after the alarm."""
    if after_alarm <= SPIN_UP:
        return -A_NET * after_alarm ** 2 / 2
    return -SPIN_UP_DISTANCE - V_FREE * (after_alarm - SPIN_UP)


def temperature(t: float) -> float:
    """?71 (°C) at ``t`` s: 200 % of rated for 3 s from 1 s (settling at 40 + 40·2²),
    then the free motor only cools (time constant 600 s)."""
    if t <= 1.0:
        return 40.0
    hot = 40.0 + 160.0 * (1.0 - math.exp(-(min(t, 4.0) - 1.0) / 600.0))
    return hot if t <= 4.0 else 40.0 + (hot - 40.0) * math.exp(-(t - 4.0) / 600.0)


@pytest.fixture()
def stopper_machine(tmp_path: Path) -> Path:
    path = tmp_path / "stoppers.toml"
    path.write_text(MACHINE)
    return path


def test_overload_on_a_machine_with_stoppers_frees_the_shaft_onto_the_stopper(
        stopper_machine: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING)
    chain = Chain(machine=str(stopper_machine))
    events = collect_events(chain, ("alarm",))
    motor = chain.motors[1]
    chain.kernel.run(until=seconds(3.9))
    assert chain.execute("?98.1") == ["Ix.1=200"]              # holding the jam at 0
    assert chain.execute("?96.1") == ["Px.1=0"]
    chain.kernel.run(until=seconds(300))
    assert [(e.time, e.text) for e in events] == [(ALARM_NS, "Ux.1=4")]
    contact = SPIN_UP + (3000 - SPIN_UP_DISTANCE) / V_FREE        # s after the alarm
    assert 0.040 < contact < 0.043
    motion = motor.axis.motion
    for after in (0.001, SPIN_UP / 2, SPIN_UP, 0.02, contact - 1e-4):
        at = ALARM_NS + round(after * NS_PER_S)
        exact = free_position((at - ALARM_NS) / NS_PER_S)
        assert motion.position_at(at) == pytest.approx(exact, abs=1e-6)
        assert abs(motion.velocity_at(at)) <= V_FREE * (1 + 1e-9)
        assert motion.torque_at(at) == 0.0
    assert motion.position_at(ALARM_NS + round(contact * NS_PER_S) + 1000) == -3000.0
    assert chain.execute("?96.1") == ["Px.1=-3000"]             # resting on the stopper
    assert chain.execute("?97.1") == ["Sx.1=0"]
    assert chain.execute("?98.1") == ["Ix.1=0"]
    assert chain.execute("?99.1") == ["Ux.1=4"]
    assert motor.thermal.temperature_at(motion, chain.kernel.now) == \
        pytest.approx(temperature(300.0), abs=1e-9)
    assert chain.execute("?71.1") == ["Temp.1=40"]               # 40.48: cooling
    assert not [r for r in caplog.records if "piece limit" in r.getMessage()]


def test_the_trace_of_the_overload_is_continuous_and_agrees_with_the_queries(
        stopper_machine: Path) -> None:
    chain = Chain(machine=str(stopper_machine))
    recorder = record(chain)
    chain.kernel.run(until=seconds(5))
    header = recorder.header()
    rows = list(recorder.rows(step=0.0005))
    t, pos, speed, torque = ([row[header.index(name)] for row in rows] for name in
                             ("time_s", "m1.position", "m1.speed", "m1.torque"))
    for i in range(1, len(t)):
        dt = t[i] - t[i - 1]
        assert abs(pos[i] - pos[i - 1]) <= V_FREE * dt * (1 + 1e-9) + 1e-9
        assert abs(speed[i]) <= V_FREE * (1 + 1e-9)
        assert -3000.0 <= pos[i] <= 0.0
        expected = 200.0 if 1.0 <= t[i] < ALARM_NS / NS_PER_S else 0.0
        assert torque[i] == pytest.approx(expected, abs=1e-9), t[i]
    assert pos[-1] == -3000.0 and speed[-1] == 0.0


def test_the_run_command_prints_no_internal_message(
        stopper_machine: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    script = tmp_path / "jam.cml"
    script.write_text("@wait 199\n?96.1\n?98.1\n?99.1\n?71.1\n")
    code, out, err = cli(capsys, "run", str(script), "--machine", str(stopper_machine))
    assert (code, err) == (0, "")
    lines = [line.split()[-1] for line in out.splitlines() if " < " in line]
    assert lines == ["Ux.1=4", "?96.1", "Px.1=-3000", "?98.1", "Ix.1=0", "?99.1", "Ux.1=4",
                     "?71.1", f"Temp.1={round(temperature(199.0))}"]
    assert "Ux.1=132" not in out


def test_overload_without_stoppers_runs_at_the_back_emf_speed_within_the_counter(
        make_chain: ChainFactory) -> None:
    chain = make_chain()
    events = collect_events(chain, ("alarm",))
    chain.inject_fault(1, "overload", torque=200)
    chain.kernel.run(until=seconds(100))
    alarm = seconds(3) + 1
    assert [(e.time, e.text) for e in events] == [(alarm, "Ux.1=4")]
    expected = free_position((seconds(100) - alarm) / NS_PER_S)
    assert chain.execute("?96.1") == [f"Px.1={round(expected)}"]      # -7 274 875
    assert chain.execute("?97.1") == ["Sx.1=-750"]                     # 75 000 pps
    assert chain.execute("?98.1") == ["Ix.1=0"]
    assert chain.execute("?71.1") == ["Temp.1=41"]                     # 40.7, cooling


def test_the_position_counter_wraps_past_the_k37_maximum(make_chain: ChainFactory) -> None:
    """ch. 3 K37: at 1000 ppr the maximum position is 42,949,672 = 2**31 counts of
    1/50000 turn; a continuous rotation past it shows the counter wrapped round, and
    a relative or absolute move then counts from where the counter is."""
    chain = make_chain()
    chain.execute("K40.1=4000, S.1=600, A.1=100, P.1=1000000000")    # 60 000 pps
    chain.execute("^.1")
    chain.kernel.run(until=seconds(800))
    half = 2 ** 31 / 50
    travelled = chain.motors[1].axis.raw_actual()           # the shaft, unwrapped
    assert half < travelled < 60000 * 800
    assert chain.motors[1].axis.position() == travelled - 2 * half
    assert chain.execute("?96.1") == [f"Px.1={round(travelled - 2 * half)}"]
    chain.execute("].1")
    chain.kernel.run(until=seconds(802))
    here = chain.motors[1].position()
    assert -half <= here < 0
    chain.execute("S.1=100, P.1+=1000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(805))
    assert chain.execute("?96.1") == [f"Px.1={here + 1000}"]
    chain.execute("S.1=600, P.1=0")                       # the counter's 0 of this turn
    chain.execute("^.1")
    assert chain.motors[1].axis.target_raw == 2 * half
    chain.kernel.run(until=seconds(1500))
    assert chain.execute("?96.1") == ["Px.1=0"]
    assert chain.execute("?99.1") == ["Ux.1=8"]


@pytest.mark.parametrize("firmware", ["cm2", "cm1"])
def test_a_load_beyond_the_torque_limit_pins_the_shaft_on_a_stopper(
        firmware: str, make_chain: ChainFactory, caplog: pytest.LogCaptureFixture) -> None:
    """M=10 allows 30 % of rated; a 200 % load drags the shaft 10 pulses onto the CCW
    stopper and holds it there: a stall at the limit (the servo, or the stepper that
    lost its steps), Ix=30, and a move away cannot free it (Pe grows)."""
    caplog.set_level(logging.WARNING)
    chain = make_chain(firmware=firmware)
    chain.motors[1].geometry.stopper_ccw = -10.0
    chain.execute("K56.1=32767, K57.1=10000, M.1=10")
    chain.inject_fault(1, "overload", torque=200)
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?96.1") == ["Px.1=-10"]
    assert chain.execute("?97.1") == ["Sx.1=0"]
    assert chain.execute("?98.1") == ["Ix.1=30"]
    chain.execute("S.1=10, P.1=500")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(3))
    assert chain.execute("?96.1") == ["Px.1=-10"]
    assert chain.execute("?95.1") == ["Pe.1=510"]
    assert chain.execute("?98.1") == ["Ix.1=30"]
    assert len(chain.motors[1].axis.motion.pieces) < 10
    assert not [r for r in caplog.records if "piece limit" in r.getMessage()]
