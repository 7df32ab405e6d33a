"""Robustness: random bank uploads and random host control while banks run.

No exception escapes, nothing deadlocks (virtual time always reaches its target), and the
motor state stays consistent: what is stored passes the checks and reads back as
itself, the memory limit holds, and after ``] ] *1`` every bank is idle and every motor
comes to rest.
"""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cml_support import lines as cml_lines
from coolmuscle.chain.daisy import Chain
from coolmuscle.cml.formatter import format_line
from coolmuscle.cml.parser import parse
from coolmuscle.motor.programs.bankcheck import check_line
from coolmuscle.sim.kernel import seconds

_garbage = st.text(st.sampled_from(list("PSAVTXIJC[]{}<>*;,:=+-/!&|^$?#.0123456789 \"")),
                   max_size=30)
_text_lines = st.one_of(cml_lines().map(format_line), _garbage,
                        st.sampled_from(["", "END", "END.2", "B1.1", "L2.1", "// note"]))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(["cm2", "rt3"]), st.lists(st.tuples(st.booleans(), st.integers(0, 32),
                                                             st.lists(_text_lines, max_size=12)),
                                                   min_size=1, max_size=6))
def test_random_bank_uploads_store_only_good_lines(firmware: str, banks: list) -> None:
    chain = Chain(motors=2, firmware=firmware)
    chain.execute("K23.1=17")
    for ladder, number, body in banks:
        chain.execute(f"{'L' if ladder else 'B'}{number}.1", origin="host")
        for text in body:
            chain.execute(text, origin="host")
        chain.execute("END", origin="host")
    motor = chain.motors[1]
    assert motor.banks.used() <= motor.banks.limit
    for ladder in (False, True):
        for number, bank in motor.banks.table(ladder).items():
            assert 1 <= number <= 30
            for line in bank:
                check_line(line, ladder=ladder, firmware=motor.firmware)
                assert parse(format_line(line))[0].statements == line.statements
    listing = chain.execute("?1000.1")
    assert listing[-1].endswith(f"/{motor.banks.limit}")


PROGRAM = [
    "B1.1", "S1.1, A1.1, P1.1", "X3.1", "P2.1, Y3.1", "I1.1, C2.1, C3.1", "T1.1", "X.1-",
    "P3.1+; S2.1, P1.1", "I2.1, W1.1, V1.1", "J4.1", "END",
    "B2.1", "S2.1, A1.1, P2.1, A2.1, P3.1", "V1.1>V2.1, C3.1, T0.1", "END",
    "B3.1", "X0.1", "Q1.1", "P2.1", "X.1-", "END",
    "B4.1", "P1.1, P1.2", "Z2.1", "O1.1", "F1.1", "[2.1", "END",
    "L1.1", "V1.1=V1.1+V2.1;", "I1.1, V2.1=V3.1, V2.1=V4.1", "V1.1>V5.1, V1.1=V4.1;", "END",
    "L2.1", "I3.1, W1.1, CL1.1", "T2.1", "JL1.1", "END",
]
DATA = ["S1.1=100", "S2.1=30", "A1.1=100", "A2.1=300", "P1.1=3000", "P2.1=-2000",
        "P3.1=500", "T1.1=50", "T2.1=20", "V2.1=1", "V3.1=1", "V4.1=-1", "V5.1=100",
        "K34.1=0033", "K63.1=5", "S.2=50", "P1.2=1000", "K27.1=000000", "K28.1=000054"]
CONTROL = ["[1.1", "[2.1", "[3.1", "[4.1", "[", "]", "}.1", ">.1", "<.1", "*", "*1", "[L1.1",
           "[L2.1", "]L.1", "[L", "[LM1.1", "]LM.1", "]1.2", "?99.1", "B100", "L100"]
_step = st.one_of(st.sampled_from(CONTROL).map(lambda c: ("cmd", c)),
                  st.tuples(st.just("input"), st.integers(1, 4)),
                  st.tuples(st.just("wait"), st.sampled_from([0, 1, 5, 50, 200, 700])))


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_step, min_size=1, max_size=40))
def test_random_control_while_banks_run(steps: list) -> None:
    chain = Chain(motors=2)
    for line in DATA + PROGRAM:
        chain.execute(line, origin="host")
    kernel = chain.kernel
    levels = [False] * 7
    for kind, arg in steps:
        if kind == "cmd":
            chain.execute(arg, origin="host")
        elif kind == "input":
            levels[arg] = not levels[arg]
            chain.set_input(1, arg, levels[arg])
        else:
            target = kernel.now + arg * 1_000_000
            kernel.run(until=target, max_events=200_000)
            assert kernel.now == target                  # no event storm at one instant
        _consistent(chain)
    for line in ("]", "]", "]L.1", "]L.1", "]LM.1", "]LM.1", "*1"):
        chain.execute(line, origin="host")
    for number in range(1, 7):
        chain.set_input(1, number, False)
    kernel.run(until=kernel.now + seconds(5), max_events=200_000)
    for motor in chain.motors.values():
        assert motor.program.state == "idle" and not motor.program.runner.busy
        assert motor.ladder.state == "idle" and motor.logic_motion.state == "idle"
        assert motor.motion_done()
    assert kernel.peek() is None or kernel.peek() > kernel.now   # nothing left to run now


def _consistent(chain: Chain) -> None:
    for motor in chain.motors.values():
        program = motor.program
        assert program.state in ("idle", "running", "paused", "stepping", "estop")
        if program.state == "idle":
            assert not program.stack and not program.runner.busy
        for runner in (motor.ladder, motor.logic_motion):
            assert runner.state in ("idle", "running", "paused")
            if runner.state == "idle":
                assert not runner.runner.busy
