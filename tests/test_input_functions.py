"""Input functions: quick and slow signals, level and edge functions.

cml-users-guide.txt ch. 3 K25-K32, K36, K23 function 2; 5.1.  Choices:
docs/fidelity.md "Inputs and outputs".
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bank_support import Rig, rig
from coolmuscle.sim.kernel import NS_PER_MS, seconds
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory

MS = NS_PER_MS


def with_functions(*lines: str, **options: object) -> Rig:
    r = rig(*lines, **options)  # type: ignore[arg-type]
    r.clear()
    return r


def pulse(r: Rig, number: int, width: float, motor: int = 1) -> None:
    r.chain.set_input(motor, number, True)
    r.wait(width)
    r.chain.set_input(motor, number, False)


def test_k25_slow_signal_after_the_delay_and_short_pulses() -> None:
    """K25 digit n x 0.1 s; "When a signal disappears within the offset time, only a
    Quick Response Signal is recognized"."""
    r = with_functions("K25.1=333352", "K31.1=000006", "K28.1=000060",
                       "B1.1", "V1.1", "END")
    pulse(r, 1, 0.19)                      # input 1 delay 0.2 s: quick only
    r.wait(0.1)
    assert r.texts() == []
    pulse(r, 1, 0.25)                      # on at 0.29 s: slow rising edge at 0.49 s
    assert r.printed == [(seconds(0.49), "V1.1=0")]
    r.clear()
    r.chain.set_input(1, 2, True)          # input 2: K28 function 6 at once
    assert r.texts() == ["V1.1=0"]
    inputs = r.motor().inputs
    assert inputs.quick[2] and not inputs.slow[2]
    r.wait(0.49)
    assert not inputs.slow[2]
    r.wait(0.02)                           # delay of input 2 is 5 x 0.1 s
    assert inputs.slow[2]


def test_k26_inverted_input_and_in_reports() -> None:
    r = with_functions("K23.1=27", "K26.1=000001")
    r.chain.set_input(1, 1, True)
    r.chain.set_input(1, 1, False)
    assert r.texts() == ["IN.1=00", "IN.1=01"]
    assert r.motor().inputs.quick[1]


@pytest.mark.parametrize(("function", "sign"), [(3, 1), (4, -1)])
def test_k27_manual_feed_while_the_input_is_on(function: int, sign: int) -> None:
    r = with_functions(f"K27.1={function}", "K49.1=20", "K43.1=100")
    trace = record(r.chain)
    r.chain.set_input(1, 1, True)
    r.wait(1)
    assert trace.sample(1, r.kernel.now).speed == pytest.approx(sign * 2000, abs=1)
    r.chain.set_input(1, 1, False)
    r.wait(0.5)
    assert r.motor().motion_done() and r.texts() == ["Ux.1=8"]


def test_k27_origin_sensor_signal() -> None:
    r = with_functions("K27.1=20")
    assert not r.motor().inputs.origin_sensor()
    r.chain.set_input(1, 2, True)
    assert r.motor().inputs.origin_sensor()


@pytest.mark.parametrize(("function", "direction"), [(6, 1), (9, -1)])
def test_k27_limit_sensors(function: int, direction: int) -> None:
    r = with_functions(f"K27.1={function}", "S.1=10", f"P.1={direction * 100000}", "^.1")
    r.wait(0.5)
    r.chain.set_input(1, 1, True)
    assert r.motor().limit_sensors[direction]
    r.wait(0.5)
    assert r.motor().motion_done()
    r.chain.set_input(1, 1, False)
    assert not r.motor().limit_sensors[direction]


def test_k27_emergency_stop_cannot_be_cancelled_by_cml_while_on() -> None:
    r = with_functions("K27.1=7", "S.1=10", "P.1=100000", "^.1")
    r.wait(0.2)
    r.chain.set_input(1, 1, True)
    assert r.texts() == ["Ux.1=512"]
    r.type("*1")
    r.wait(0.1)
    assert r.motor().status == 512
    r.chain.set_input(1, 1, False)
    assert r.motor().status == 8 and not r.motor().estopped


def test_k27_emergency_stop_input_pauses_and_resumes_the_bank() -> None:
    r = with_functions("K27.1=7", "S.1=100", "P1.1=1000", "P2.1=2000", "B1.1", "P1.1",
                       "P2.1", "V1.1", "END", "[1.1")
    r.wait(0.05)
    r.chain.set_input(1, 1, True)
    r.wait(0.5)
    assert r.motor().program.state == "estop"
    r.chain.set_input(1, 1, False)
    r.wait(1)
    assert r.texts() == ["Ux.1=512", "Ux.1=8", "V1.1=0"]    # line 2 (P2) then line 3


def test_k27_stop_program_bank_is_two_pauses() -> None:
    r = with_functions("K27.1=8", "S.1=10", "P1.1=100000", "B1.1", "P1.1", "END", "[1.1")
    r.wait(0.2)
    r.chain.set_input(1, 1, True)
    assert r.motor().program.state == "idle"
    r.wait(0.5)
    assert r.motor().motion_done()
    r.type("[")
    assert r.motor().program.state == "idle"


def test_k28_alarm_reset_and_program_pause_then_bank_1_resumes() -> None:
    """K28 1: "Re-start from paused position is possible by 6: Execute Program Bank 1"."""
    r = with_functions("K28.1=61", "S.1=100", "P1.1=5000", "B1.1", "P1.1", "V1.1", "END",
                       "[1.1")
    r.wait(0.2)
    r.motor().raise_alarm(4)
    pulse(r, 1, 0.01)
    assert r.motor().alarm == 0 and r.motor().program.state == "paused"
    r.wait(0.5)
    pulse(r, 2, 0.01)                     # function 6: resume the paused bank
    r.wait(1)
    assert r.texts()[-2:] == ["Ux.1=8", "V1.1=0"]


def test_k28_k29_motor_free_and_enable() -> None:
    r = with_functions("K28.1=2", "K29.1=2")
    r.chain.set_input(1, 1, True)
    assert r.motor().status == 16
    r.chain.set_input(1, 1, False)
    assert r.motor().status == 8


def test_k28_counter_reset() -> None:
    r = with_functions("K28.1=3", "S.1=100", "P.1=1234", "^.1")
    r.wait(0.5)
    pulse(r, 1, 0.01)
    assert r.chain.execute("?96.1") == ["Px.1=0"]


def test_k28_next_and_previous_line() -> None:
    """K28 4: "Rising Edge: Execute line 1, Next Rising Edge: Execute Line 2"."""
    r = with_functions("K28.1=54", "B1.1", "V1.1", "V2.1", "END")
    for _ in range(3):
        pulse(r, 1, 0.01)
    pulse(r, 2, 0.01)
    pulse(r, 2, 0.01)
    assert r.texts() == ["V1.1=0", "V2.1=0", "End.1", "Can't back!", "Can't back!"]


def test_k31_k32_slow_edges_run_banks() -> None:
    r = with_functions("K31.1=6", "K32.1=7", "B1.1", "V1.1", "END")
    r.chain.set_input(1, 1, True)
    r.wait(0.29)
    assert r.texts() == []
    r.wait(0.02)
    assert r.texts() == ["V1.1=0"]


def test_k28_origin_search() -> None:
    r = with_functions("K28.1=7", "S.1=100", "P.1=500", "^.1")
    r.motor().geometry.stopper_ccw = -700.0       # the search (K46=0, CCW) finds it
    r.motor().axis.refresh()
    r.wait(0.5)
    pulse(r, 1, 0.01)
    r.wait(2)
    assert r.texts()[-2:] == ["Origin.1=0", "Ux.1=8"]
    assert r.chain.execute("?96.1") in (["Px.1=0"], ["Px.1=1"], ["Px.1=-1"])
    assert abs(r.motor().axis.raw_actual() + 700.0) < 1e-3


@pytest.mark.parametrize(("k36", "expected"), [(0, ["Px.1=10", "Px.1=0"]),
                                               (2, ["V2.1=0", "V3.1=0"])])
def test_k28_jog_or_banks_2_and_3(k36: int, expected: list[str]) -> None:
    """K28 8/9: jog K50 pulses CW/CCW; with K36 = 2 or 3, program banks 2 and 3."""
    r = with_functions(f"K36.1={k36}", "K28.1=98", "K50.1=10", "B2.1", "V2.1", "END",
                       "B3.1", "V3.1", "END")
    seen = []
    pulse(r, 1, 0.01)
    r.wait(0.5)
    seen += r.chain.execute("?96.1") if k36 == 0 else []
    pulse(r, 2, 0.01)
    r.wait(0.5)
    seen += r.chain.execute("?96.1") if k36 == 0 else []
    assert (seen if k36 == 0 else [t for t in r.texts() if not t.startswith("Ux")]) == expected


def test_input_levels_at_power_up_hold_their_level_functions(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain(state_dir=tmp_path)
    chain.execute("K26.1=000001")
    chain.execute("K27.1=000007")
    chain.close()
    again = make_chain(state_dir=tmp_path)   # input 1 not wired: inverted, so on: e-stop
    assert again.motors[1].status == 512
    again.close()
