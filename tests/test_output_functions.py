"""Output functions K34 with the output logic of K33, and the K23 output reports.

cml-users-guide.txt ch. 3 K23 (function 4: "only for general output"), K33, K34, K55
(in position before the target), K73; 6.6 ?50 / ?51-?54.  Rotation pulses (K34 = 7) and
push motion (9) belong to other models.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bank_support import Rig, rig
from coolmuscle.motor.signals.io import DigitalIO, digit
from coolmuscle.motor.state.firmware import CM2
from coolmuscle.motor.state.output_functions import (
    CML_OUTPUT_FUNCTIONS,
    OUT_ANALOG,
    OUT_FOLLOWS_O1,
    OUT_FOLLOWS_O2,
    OUT_GENERAL,
    OUT_NONE,
)
from coolmuscle.motor.state.param_table import ParamTable
from coolmuscle.sim.kernel import NS_PER_MS, seconds
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory, collect_events

MS = NS_PER_MS


def outputs(r: Rig) -> str:
    (reply,) = r.chain.execute("?50.1")
    return reply


def test_k34_1_in_position_output() -> None:
    r = rig("K34.1=0001", "S.1=100", "P.1=1000")
    assert outputs(r) == "OUT.1=01"
    r.type("^.1")
    assert outputs(r) == "OUT.1=00"
    r.wait(0.5)
    assert outputs(r) == "OUT.1=01"


def test_k33_low_active_inverts_the_port() -> None:
    r = rig("K34.1=0001", "K33.1=1110", "S.1=100", "P.1=1000", "^.1")
    assert outputs(r) == "OUT.1=01"            # moving: signal off, low active: port on
    r.wait(0.5)
    assert outputs(r) == "OUT.1=00"
    assert r.chain.execute("?51.1") == ["OUT1.1=0"]


def test_k34_2_alarm_and_8_motor_free() -> None:
    r = rig("K34.1=0082")
    assert outputs(r) == "OUT.1=00"
    r.motor().raise_alarm(4)
    assert outputs(r) == "OUT.1=03"            # alarm, and the motor is free
    r.type("(.1")
    assert outputs(r) == "OUT.1=00"
    r.type(").1")
    assert outputs(r) == "OUT.1=02"


def test_k34_3_general_outputs_from_banks_and_k23_reports() -> None:
    """K23 4: "Automatically report ... when output status changes. only for general
    output": O/F from a program and a ladder bank report, in-position does not."""
    r = rig("K23.1=29", "K34.1=0331", "S.1=100", "P1.1=1000", "B1.1", "O2.1", "P1.1", "END",
            "L1.1", "I1.1, O3.1, F3.1", "END", "K63.1=10")
    r.clear()
    r.type("[1.1")
    r.wait(0.5)
    assert r.texts() == ["OUT.1=03", "Ux.1=8"]
    r.type("[L1.1")
    r.chain.set_input(1, 1, True)
    r.wait(0.015)
    assert r.texts()[-1] == "OUT.1=07"
    r.chain.set_input(1, 1, False)
    r.wait(0.015)
    assert r.texts()[-1] == "OUT.1=03"
    assert r.texts().count("OUT.1=07") == 1     # reported on change only


def test_k34_4_origin_done_only_after_an_origin_search() -> None:
    r = rig("K34.1=0004")
    assert outputs(r) == "OUT.1=00"
    r.motor().origin_done = True              # set by the origin search model (5.3)
    assert outputs(r) == "OUT.1=01"


def test_k34_6_merge_pulses_of_k73_at_passing_points_only() -> None:
    """K73: "Pulse signals are sent out only at the passing points but not at the
    starting and end points"; the pulse lasts K73 ms."""
    r = rig("K34.1=0006", "K73.1=20", "S1.1=100", "A1.1=100", "P1.1=2000", "P2.1=4000",
            "P3.1=6000", "B1.1", "S1.1, A1.1, P1.1, P2.1, P3.1", "END")
    trace = record(r.chain)
    r.type("[1.1")
    r.until(2)
    changes = []
    last = 0
    for t in range(0, seconds(2), MS // 4):
        out = trace.sample(1, t).outputs
        if out != last:
            changes.append((t, out))
            last = out
    (on1, _), (off1, _), (on2, _), (off2, _) = changes
    assert off1 - on1 == 20 * MS and off2 - on2 == 20 * MS
    assert on2 - on1 == 200 * MS               # 2000 pulses at 10000 pps
    assert r.times("Ux.1=8") and r.times("Ux.1=8")[0] > off2


@pytest.mark.parametrize("function", [0, 5])
def test_k34_0_and_5_have_no_function(function: int) -> None:
    r = rig(f"K34.1=000{function}", "O1.1")
    assert outputs(r) == "OUT.1=00"


# -- CM1: cm1-ethernetip-interface-manual.txt Appendix A K33, K34 ----------------------
def test_cm1_appendix_a_factory_outputs_are_off_and_k34_0_follows_its_own_command(
        make_chain: ChainFactory) -> None:
    """A CM1 at its factory K33=0, K34=0 read ``OUT.1=03`` (its K33 0
    was taken for CM2's "Low Active").  Appendix A: "K33 Output Logic 0:Normally open
    1: Normally closed" (open: the port is on while its signal is) and "K34 ... 0:Command"
    (the output follows the commands ``O#``/``F#`` of its own number)."""
    chain = make_chain(firmware="cm1")
    assert chain.execute("K33.1") == ["K33.1=0"] and chain.execute("K34.1") == ["K34.1=0"]
    assert chain.execute("?50.1") == ["OUT.1=00"]
    chain.execute("O2.1")
    assert chain.execute("?50.1") == ["OUT.1=02"]
    assert chain.execute("?51.1") == ["OUT1.1=0"] and chain.execute("?52.1") == ["OUT2.1=1"]
    chain.execute("O1.1")
    assert chain.execute("?50.1") == ["OUT.1=03"]
    chain.execute("F2.1")
    assert chain.execute("?50.1") == ["OUT.1=01"]
    chain.execute("K33.1=1")                        # normally closed: the inverse
    assert chain.execute("?50.1") == ["OUT.1=02"]


def test_cm1_k34_digit_3_follows_o1_f1_and_4_follows_o2_f2(make_chain: ChainFactory) -> None:
    """CM1 manual, K34 (N2 output 2, N1 output 1): "3:CML O1/F1 4:CML O2/F2": the digit
    names the command an output follows, whichever output it is (on CM2, 3 is general
    use of the output's own number and 4 the origin-search output)."""
    chain = make_chain(firmware="cm1")              # K33=0, normally open: port = signal
    chain.execute("K34.1=43")                       # output 2: O2/F2, output 1: O1/F1
    assert chain.execute("?50.1") == ["OUT.1=00"]
    chain.execute("O2.1")
    assert chain.execute("?50.1") == ["OUT.1=02"]
    chain.execute("O1.1")
    assert chain.execute("?50.1") == ["OUT.1=03"]
    chain.execute("F2.1")
    assert chain.execute("?50.1") == ["OUT.1=01"]
    chain.execute("K34.1=33")                       # both outputs follow O1/F1
    assert chain.execute("?50.1") == ["OUT.1=03"]
    chain.execute("F1.1")
    assert chain.execute("?50.1") == ["OUT.1=00"]
    chain.execute("O2.1")                           # no output follows O2 now: ignored
    assert chain.execute("?50.1") == ["OUT.1=00"]
    cm2 = make_chain()
    cm2.execute("K33.1=1111")
    cm2.execute("K34.1=0043")                       # CM2: output 1 general, 2 origin done
    cm2.execute("O1.1")
    cm2.execute("O2.1")
    assert cm2.execute("?50.1") == ["OUT.1=01"]


def test_cm1_k34_5_is_the_analog_output_no_digital_signal(make_chain: ChainFactory) -> None:
    """Appendix A K34 "5:Analog Output" (CM2's 5 is "—"): the output carries the K35
    analog value, no digital signal; ``O#`` does not reach it."""
    chain = make_chain(firmware="cm1")
    chain.execute("K34.1=55")
    chain.execute("O1.1")
    chain.execute("O2.1")
    assert chain.execute("?50.1") == ["OUT.1=00"]
    chain.execute("K33.1=1")
    assert chain.execute("?50.1") == ["OUT.1=03"]


def test_cm1_k34_9_is_on_when_the_push_reaches_its_torque_not_while_it_approaches(
        make_chain: ChainFactory) -> None:
    """Appendix A K34 "9: Torque Limit reached - Push Mode Only"; CML ch. 3 K34 9 "In Push
    Motion" is on from the ``Q`` (4.1.4).  The object is a stopper at 5000 pulses; at
    2000 pps the shaft meets it after 2.5 s and presses at the K60 level (K61=30001:
    endless, Appendix A K61)."""
    from coolmuscle.chain.machine import parse_machine
    machine = "[[axis]]\n[axis.stoppers]\ncw = 5000\n"
    cm1 = make_chain(firmware="cm1", machine=parse_machine(machine))
    cm2 = make_chain(machine=parse_machine(machine))
    for chain, endless in ((cm1, 30001), (cm2, 0)):
        chain.execute(f"K34.1=9, K61.1={endless}, P1.1=8000, S.1=20, A.1=100")
        chain.execute("Q1.1")
        chain.kernel.run(until=seconds(1))
        assert chain.execute("?99.1") == ["Ux.1=32"]               # pushing, not yet there
    assert cm1.execute("?51.1") == ["OUT1.1=0"]
    assert cm2.execute("?51.1") == ["OUT1.1=1"]
    for chain in (cm1, cm2):
        chain.kernel.run(until=seconds(4))
        assert chain.execute("?51.1") == ["OUT1.1=1"]              # pressing the object


def test_cm1_k26_and_k33_are_one_logic_for_every_input_and_output(make_chain: ChainFactory) -> None:
    """CM1 manual: "K26 Invert input signal 0/1", "K33 Output Logic 0:Normally open
    1: Normally closed": one value, not a digit per channel as on CM2."""
    chain = make_chain(firmware="cm1")
    assert chain.execute("?70.1") == ["IN.1=00"]
    chain.execute("K26.1=1")
    assert chain.execute("?70.1") == ["IN.1=0F"]                # all four inverted
    chain.set_input(1, 3, True)
    assert chain.execute("?70.1") == ["IN.1=0B"]
    chain.execute("K34.1=43")
    assert chain.execute("?50.1") == ["OUT.1=00"]               # K33=0: both normally open
    chain.execute("K33.1=1")
    assert chain.execute("?50.1") == ["OUT.1=03"]               # both normally closed


def test_ch3_k55_in_position_is_detected_before_reaching_the_target(
        make_chain: ChainFactory) -> None:
    # K55: "in-position is detected when the current position is within the set range
    # against the target position" ... "In-Position may be detected before reaching the
    # target position"; "K55=5 ... In-position signals will be sent out between 995 and
    # 1005, when the target position is 1000."
    chain = make_chain()
    events = collect_events(chain)
    trace = record(chain)
    chain.execute("K23.1=1, K34.1=1, K55.1=100, S.1=10, A.1=10, P.1=10000")  # out 1: in-pos
    chain.execute("^.1")
    end_of_command = chain.motors[1].axis.profile.end_ns
    chain.kernel.run(until=seconds(12))
    at = next(e.time for e in events if e.text == "Ux.1=8")
    assert at < end_of_command - seconds(0.02)            # the command still runs then
    assert abs(trace.sample(1, at).position - 10000) <= 100
    assert abs(trace.sample(1, at - 1000).position - 10000) > 100
    assert trace.sample(1, at).command < 10000
    # the in-position output (K34 function 1) is on from that instant
    chain2 = make_chain()
    chain2.execute("K34.1=1, K55.1=100, S.1=10, A.1=10, P.1=10000")
    chain2.execute("^.1")
    chain2.kernel.run(until=at - 1000)
    assert chain2.execute("?51.1") == ["OUT1.1=0"] and chain2.execute("?99.1") == ["Ux.1=0"]
    chain2.kernel.run(until=at)
    assert chain2.execute("?51.1") == ["OUT1.1=1"] and chain2.execute("?99.1") == ["Ux.1=8"]


def _digits(low: int, high: int, count: int) -> st.SearchStrategy[int]:
    """A digit-wise K value (ch. 3): ``count`` digits, each ``low..high``."""
    return st.lists(st.integers(low, high), min_size=count, max_size=count).map(
        lambda ds: sum(d * 10 ** i for i, d in enumerate(ds)))


_K26, _K33, _K34 = _digits(0, 3, 6), _digits(0, 1, 4), _digits(0, 9, 4)


@settings(max_examples=200, deadline=None)
@given(k26=_K26, k33=_K33, k34=_K34, later=st.tuples(_K26, _K33, _K34),
       levels=st.lists(st.booleans(), min_size=6, max_size=6),
       general=st.lists(st.booleans(), min_size=4, max_size=4))
def test_ch3_k26_k33_k34_words_are_the_digits_read_afresh(
        k26: int, k33: int, k34: int, later: tuple[int, int, int], levels: list[bool],
        general: list[bool]) -> None:
    """?70 and ?50 read K26/K33/K34 digit by digit (ch. 3) from the motor's K table,
    whatever values came before (DigitalIO keeps the digits of the values it decoded
    last)."""
    params = ParamTable(CM2)
    io = DigitalIO(6, 4, params, lambda fn, n: (fn + n) % 2 == 0, CML_OUTPUT_FUNCTIONS)
    io.levels[1:] = levels
    io.general[1:] = general
    for values in ((k26, k33, k34), later, (k26, k33, k34)):
        for number, value in zip((26, 33, 34), values):
            params.set(number, value)
        inputs = sum(1 << (n - 1) for n in range(1, 7)
                     if levels[n - 1] != (digit(values[0], n) % 2 == 1))
        outputs = 0
        for n in range(1, 5):
            fn = CML_OUTPUT_FUNCTIONS[digit(values[2], n)]
            follows = {OUT_GENERAL: n, OUT_FOLLOWS_O1: 1, OUT_FOLLOWS_O2: 2}.get(fn)
            signal = general[follows - 1] if follows is not None else (
                False if fn in (OUT_NONE, OUT_ANALOG) else (fn + n) % 2 == 0)
            if signal != (digit(values[1], n) == 0):
                outputs |= 1 << (n - 1)
        assert io.input_word() == inputs
        assert io.output_word() == outputs
