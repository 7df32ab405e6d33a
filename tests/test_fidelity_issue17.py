"""Fidelity points where the manual is read closely, each against its words.

cml-users-guide.txt ch. 3 K20/K23, K37, K55, 2.2.1/2.2.2 "V"; cm-banks-rt3.txt 3.6;
choices in docs/fidelity.md ("Fidelity decisions: K37 40..70, K20 prompts, ...").
"""

from __future__ import annotations

import math

from coolmuscle.chain.daisy import Chain
from coolmuscle.device.api import Event
from coolmuscle.sim.kernel import NS_PER_S, seconds
from coolmuscle.tools.trace.recorder import record


def _chain(**options: object) -> tuple[Chain, list[Event]]:
    chain = Chain(**options)  # type: ignore[arg-type]
    events: list[Event] = []
    chain.subscribe(events.append)
    return chain, events


def _texts(events: list[Event], kinds: tuple[str, ...] = ("status", "alarm", "message",
                                                           "reply")) -> list[str]:
    return [e.text for e in events if e.kind in kinds]


def _first_time(events: list[Event], text: str) -> int:
    return next(e.time for e in events if e.text == text)


# -- K55 ------------------------------------------------------------------------------

def test_ch3_k55_in_position_is_detected_before_reaching_the_target() -> None:
    # K55: "in-position is detected when the current position is within the set range
    # against the target position" ... "In-Position may be detected before reaching the
    # target position"; "K55=5 ... In-position signals will be sent out between 995 and
    # 1005, when the target position is 1000."
    chain, events = _chain()
    trace = record(chain)
    chain.execute("K23.1=1, K34.1=1, K55.1=100, S.1=10, A.1=10, P.1=10000")  # out 1: in-pos
    chain.execute("^.1")
    end_of_command = chain.motors[1].axis.profile.end_ns
    chain.kernel.run(until=seconds(12))
    at = _first_time(events, "Ux.1=8")
    assert at < end_of_command - seconds(0.02)            # the command still runs then
    assert abs(trace.sample(1, at).position - 10000) <= 100
    assert abs(trace.sample(1, at - 1000).position - 10000) > 100
    assert trace.sample(1, at).command < 10000
    # the in-position output (K34 function 1) is on from that instant
    chain2, events2 = _chain()
    chain2.execute("K34.1=1, K55.1=100, S.1=10, A.1=10, P.1=10000")
    chain2.execute("^.1")
    chain2.kernel.run(until=at - 1000)
    assert chain2.execute("?51.1") == ["OUT1.1=0"] and chain2.execute("?99.1") == ["Ux.1=0"]
    chain2.kernel.run(until=at)
    assert chain2.execute("?51.1") == ["OUT1.1=1"] and chain2.execute("?99.1") == ["Ux.1=8"]


def test_ch3_k55_the_next_bank_line_starts_at_in_position() -> None:
    # K55: "When the range is set to small, In-Position may not be detected and can not
    # execute the next step in a program": the next step follows in-position
    chain, events = _chain()
    for line in ("K23.1=17, K55.1=100, S1.1=10, A1.1=10, P1.1=10000, P2.1=0",
                 "B1.1", "S1.1, A1.1, P1.1", "?96.1", "END"):
        chain.execute(line)
    chain.execute("[1.1")
    end_of_command = chain.motors[1].axis.profile.end_ns
    chain.kernel.run(until=seconds(12))
    at = _first_time(events, "Ux.1=8")
    px = next(e for e in events if e.text.startswith("Px.1="))
    assert px.time == at < end_of_command
    assert 9900 <= int(px.text.split("=")[1]) < 10000


def test_ch3_k55_a_path_through_its_target_is_not_in_position_on_the_way() -> None:
    # only the final approach counts: a merge out to 10000 and back to 0 from 0 is not
    # in position at its start, though it starts within K55 of its target
    chain, events = _chain()
    for line in ("K23.1=1, S1.1=100, A1.1=100, P1.1=3000, P2.1=0", "B1.1",
                 "S1.1, A1.1, P1.1, P2.1", "END"):
        chain.execute(line)
    chain.execute("[1.1")
    chain.kernel.run(until=seconds(0.1))
    assert chain.execute("?99.1") == ["Ux.1=0"]
    chain.kernel.run(until=seconds(3))
    assert _texts(events, ("status",)) == ["Ux.1=8"]
    assert abs(chain.motors[1].position()) <= 5


# -- K37 --------------------------------------------------------------------------------

def test_ch3_k37_40_to_70_incremental_motion_cannot_be_executed() -> None:
    # K37: "When it is set to 40-70, the incremental motion cannot be executed."
    # "Continuous motion (P=1000000000) is still available in any resolution."
    chain, events = _chain()
    chain.execute("K23.1=17, K37.1=43, S.1=10, A.1=100")
    assert chain.execute("P.1+=100") == ["error00.1: Out Of Range!!"]
    assert chain.execute("P.1-=100") == ["error00.1: Out Of Range!!"]
    assert chain.execute("P.1") == ["P.1=0"]
    for line in ("P1.1=500", "S1.1=10", "A1.1=100", "B1.1", "S1.1, A1.1, P1.1+", "?96.1",
                 "END"):
        chain.execute(line)
    chain.execute("[1.1")
    chain.kernel.run(until=seconds(2))
    assert "error00.1: Out Of Range!!" in _texts(events)
    assert chain.execute("?96.1") == ["Px.1=0"]          # it did not move
    chain.execute("P.1=1000000000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(3))
    assert chain.execute("?97.1") == ["Sx.1=10"]          # continuous rotation runs
    # at K37 = 3 the same lines move
    chain2, _ = _chain()
    chain2.execute("S.1=10, A.1=100")
    chain2.execute("P.1+=100")
    assert chain2.execute("P.1") == ["P.1=100"]


# -- K20 / K23 16 ----------------------------------------------------------------------

def test_ch3_k23_16_k20_change_asks_change_baud_rate_y_n() -> None:
    # K23 16 confirmation messages: "Change Baud Rate ?? XXX kbps (Y/N)  Confirmation
    # message when the baud rate is changed by K20"; K20 table 1 = 9.6 kbps
    chain, _ = _chain()
    chain.execute("K23.1=17, S.1=10, A.1=100, P.1=1000")
    assert chain.execute("K20.1=1") == ["Change Baud Rate ?? 9.6 kbps (Y/N)"]
    assert chain.motors[1].k(20) == 0                     # not changed before the answer
    assert chain.execute("Y") == []                        # the answer, not the Y command
    assert chain.execute("K20.1") == ["K20.1=1"]
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?96.1") == ["Px.1=0"]           # no Y motion was started
    assert chain.execute("K20.1=4") == ["Change Baud Rate ?? 115.2 kbps (Y/N)"]
    assert chain.execute("n") == []
    assert chain.execute("K20.1") == ["K20.1=1"]
    # another line instead of an answer cancels the change and runs
    assert chain.execute("K20.1=0") == ["Change Baud Rate ?? 38.4 kbps (Y/N)"]
    assert chain.execute("?99.1") == ["Ux.1=8"]
    assert chain.execute("K20.1") == ["K20.1=1"]
    assert chain.execute("K20.1=6") == ["error00.1: Out Of Range!!"]


def test_ch3_k20_without_k23_16_changes_at_once() -> None:
    chain, _ = _chain()
    assert chain.execute("K20.1=2") == []
    assert chain.execute("K20.1") == ["K20.1=2"]


# -- V display --------------------------------------------------------------------------

def test_2_2_1_v_alone_in_a_bank_displays_the_state_value() -> None:
    # 2.2.1 / 2.2.2 "V": "When this command is used alone, it displays the specified
    # variable data. This is used for a message sent to a host."
    chain, events = _chain()
    for line in ('K23.1=17', 'V4.1="Px"', "S.1=10", "A.1=10", "P.1=1234"):
        chain.execute(line)
    chain.execute("^.1")
    chain.kernel.run(until=seconds(3))
    for line in ("B1.1", "V4.1", "V5.1=V4.1", "V5.1", "END"):
        chain.execute(line)
    events.clear()
    chain.execute("[1.1")
    chain.kernel.run(until=seconds(4))
    assert _texts(events) == ["V4.1=1234", "V5.1=1234"]
    assert chain.execute("V4.1") == ['V4.1="Px"']         # direct mode: what was assigned


def test_2_2_3_ladder_v_alone_displays_the_state_value() -> None:
    chain, events = _chain()
    for line in ("K23.1=17, K63.1=100", 'V4.1="Ux"', "L1.1", "V4.1", "END"):
        chain.execute(line)
    events.clear()
    chain.execute("[L1.1")
    chain.kernel.run(until=seconds(0.15))
    assert _texts(events) == ["V4.1=8", "V4.1=8"]


# -- RT3 logic motion -------------------------------------------------------------------

def test_rt3_3_6_logic_motion_bank_scans_every_1_ms_and_its_sine_has_that_period() -> None:
    # RT3 3.6: "These banks execute on 1 ms intervals and are independent of K87" and of
    # its 6-step example: "in this case the timing is less than 1ms"
    chain, _ = _chain(firmware="rt3")
    for line in ("K87.1=100", "K56.1=32767", 'V3="Dx"', "V2=10", "L1", "V1=V1+V2",
                 "V3=U2(V1)", "END"):
        chain.execute(line)
    trace = record(chain)
    chain.execute("[LM1")
    chain.kernel.run(until=seconds(2.5))
    motor = chain.motors[1]
    assert motor.logic_motion.scans == 2501
    # V1 grows by 10 a ms: U2 = 10000 cos(2π V1/10000) repeats every 1000 ms
    ups = [t for t in range(seconds(0.5), seconds(2.5), 1_000_000)
           if trace.sample(1, t).target < 0 <= trace.sample(1, t + 1_000_000).target]
    assert len(ups) == 2 and math.isclose((ups[1] - ups[0]) / NS_PER_S, 1.0, abs_tol=0.002)


# -- trace ------------------------------------------------------------------------------

def test_trace_analog_out_uses_the_k35_of_each_instant() -> None:
    # ch. 3 K35 changed midway: the first part of the trace keeps its own K35
    chain, _ = _chain()
    trace = record(chain)
    chain.execute("K35.1=2, S.1=10, A.1=100, P.1=5000")   # position output
    chain.execute("^.1")
    chain.kernel.run(until=seconds(1))
    early = trace.sample(1, seconds(0.5)).analog_out
    chain.execute("K35.1=8")                               # torque output
    chain.kernel.run(until=seconds(7))
    assert trace.sample(1, seconds(0.5)).analog_out == early
    assert early != 2.5                                    # a position reads off centre
    assert trace.sample(1, seconds(6.5)).analog_out == 2.5  # torque 0 at rest: centre
