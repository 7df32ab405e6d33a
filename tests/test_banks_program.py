"""The program bank executor: lines, merge motion, loops, calls, waits, host control.

cml-users-guide.txt 2.1.2, 2.2.1-2.2.2 ("V" alone), 4.1-4.3, 6.3, 6.5, ch. 3 K55 (the next
line at in-position); docs/fidelity.md "Banks and ladder".
Facts come from the trace recorder (positions, speeds at exact instants) and the lines
the motor prints.
"""

from __future__ import annotations

import pytest

from bank_support import Rig, enters_window
from bank_support import rig as _rig
from coolmuscle.sim.kernel import NS_PER_MS, seconds
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory, collect_events

MS = NS_PER_MS


def rig(*lines: str, **options: object) -> Rig:
    """A chain with ``lines`` typed; what setting up printed ([End of Bank]) forgotten."""
    split = len(lines)
    while split and lines[split - 1].startswith("["):
        split -= 1
    typed, starts = lines[:split], lines[split:]
    result = _rig(*typed, **options)  # type: ignore[arg-type]
    assert "error" not in " ".join(result.texts()), result.texts()
    result.clear()
    result.type(*starts)
    return result


def test_2_2_a_line_waits_for_in_position_then_the_timer() -> None:
    r = rig("S1.1=100", "A1.1=100", "P1.1=10000", "P2.1=0", "T1.1=1000",
            "B1.1", "S1.1, A1.1, P1.1", "T1.1", "P2.1", "END")
    trace = record(r.chain)
    r.type("[1.1")
    r.until(4)
    arrivals = r.times("Ux.1=8")
    # ch. 3 K55: in position when the actual position is within 5 pulses of the
    # target, a few ms before the 1.1 s command ends; T1 runs from there
    first, second = arrivals
    assert enters_window(trace, 1, first, 10000) and seconds(1.08) < first < seconds(1.1)
    assert trace.sample(1, first + 999 * MS).command == 10000
    assert trace.sample(1, first + 1000 * MS + MS).command < 10000
    assert enters_window(trace, 1, second, 0)
    assert second - (first + seconds(1)) < seconds(1.1)


def test_4_1_2_merge_motion_passes_points_without_stopping() -> None:
    r = rig("S1.1=100", "S2.1=50", "A1.1=100", "P1.1=10000", "P2.1=20000",
            "B2.1", "S1.1, A1.1, P1.1, S2.1, P2.1", "END")
    trace = record(r.chain)
    r.type("[2.1")
    r.until(5)
    assert len(r.times("Ux.1=8")) == 1
    end = r.times("Ux.1=8")[0]
    speeds = [trace.sample(1, t).speed for t in range(seconds(0.15), end - seconds(0.1), MS)]
    assert min(speeds) > 4900          # never below S2 = 5000 pps (servo lag aside)
    assert trace.sample(1, seconds(0.5)).speed == pytest.approx(10000, abs=1)


def test_4_1_3_second_a_is_the_deceleration() -> None:
    r = rig("S1.1=100", "A1.1=20", "A2.1=400", "P1.1=5000", "P2.1=20000",
            "B3.1", "S1.1, A1.1, P1.1, A2.1, P2.1", "END")
    trace = record(r.chain)
    r.type("[3.1")
    r.until(3)
    # acceleration 20 kpps²: 10000 pps after 0.5 s; deceleration 400 kpps²: 25 ms
    assert trace.sample(1, seconds(0.25)).command == pytest.approx(625, abs=0.01)
    end = r.times("Ux.1=8")[0]
    command_end = seconds(0.5 + 17375 / 10000 + 0.025)
    assert enters_window(trace, 1, end, 20000) and command_end - seconds(0.01) < end < command_end


def test_merge_across_semicolon_is_the_same_motion() -> None:
    data = ("S1.1=100", "S2.1=40", "A1.1=100", "P1.1=6000", "P2.1=9000")
    one = rig(*data, "B1.1", "S1.1, A1.1, P1.1, S2.1, P2.1", "END", "[1.1")
    two = rig(*data, "B1.1", "S1.1, A1.1, P1.1;", "S2.1, P2.1", "END", "[1.1")
    one.until(3)
    two.until(3)
    assert one.times("Ux.1=8") == two.times("Ux.1=8") != []


def test_relative_p_starts_from_the_previous_waypoint() -> None:
    r = rig("S.1=100", "P2.1=1000", "B1.1", "P2.1+, P2.1+", "P2.1+", "END", "[1.1")
    r.until(2)
    assert len(r.times("Ux.1=8")) == 2
    assert r.chain.execute("?96.1") in (["Px.1=3000"], ["Px.1=2999"], ["Px.1=3001"])


def test_2_2_2_x_loops_and_bank_end() -> None:
    r = rig("S.1=100", "P1.1=500", "P2.1=0", "B1.1", "X3.1", "P1.1", "P2.1", "X.1-",
            "V1.1", "END", "[1.1")
    r.until(3)
    assert len(r.times("Ux.1=8")) == 6
    assert r.texts()[-1] == "V1.1=0"
    assert r.motor().program.state == "idle"


def test_6_3_missing_x_minus_loops_to_the_end() -> None:
    r = rig("B1.1", "V1.1", "X2.1", "V2.1", "END", "[1.1")
    r.until(1)
    assert r.texts() == ["V1.1=0", "V2.1=0", "V2.1=0"]


def test_2_2_2_loops_nest_up_to_10() -> None:
    """An 11th nested X is not made ("the motion is not guaranteed"): 2^10 bodies."""
    r = rig("B1.1", *["X2.1"] * 11, "V1.1", *["X.1-"] * 11, "END", "[1.1")
    r.until(60)
    assert r.texts().count("V1.1=0") == 1024
    assert r.motor().program.state == "idle"


def test_x0_loops_forever_and_lines_take_their_steps() -> None:
    """A loop without motion still takes time: 3 steps + 1 step = 1 ms a round (RT3 3.4)."""
    r = rig("V2.1=1", "B1.1", "X0.1", "V1.1=V1.1+V2.1", "X.1-", "END", "[1.1")
    r.until(1)
    assert r.chain.get_register(1, "V", 1) == 1000
    r.type("]", "]")
    r.until(2)
    assert r.chain.get_register(1, "V", 1) == 1000


def test_2_2_2_call_returns_jump_does_not() -> None:
    r = rig("V1.1=1", "V2.1=2", "V3.1=3", "B1.1", "C2.1", "V1.1", "J3.1", "V2.1", "END",
            "B2.1", "V2.1", "END", "B3.1", "V3.1", "END", "[1.1")
    r.until(1)
    assert r.texts() == ["V2.1=2", "V1.1=1", "V3.1=3"]


def test_2_2_2_calls_nest_under_10_and_never_recurse() -> None:
    lines = []
    for bank in range(1, 12):
        lines += [f"B{bank}.1", f"V{bank}.1", f"C{bank + 1}.1", "END"]
    lines += ["B12.1", "C1.1", "V12.1", "END"]   # bank 12 would call bank 1 again
    r = rig(*lines, "[1.1")
    r.until(1)
    assert r.texts() == [f"V{n}.1=0" for n in range(1, 11)]


def test_call_of_a_missing_bank_is_error05_and_the_bank_goes_on() -> None:
    r = rig("B1.1", "C9.1", "V1.1", "END", "[1.1")
    r.until(1)
    assert r.texts() == ["error05.1: Program Bank does not exist!!", "V1.1=0"]


def test_start_bank_inside_a_bank_jumps() -> None:
    r = rig("B1.1", "[2.1", "V1.1", "END", "B2.1", "V2.1", "END", "[1.1")
    r.until(1)
    assert r.texts() == ["V2.1=0"]


def test_w0_waits_while_true_and_reacts_to_the_change_at_once() -> None:
    """4.2.4 with a V condition: the host's assignment ends the wait at that instant."""
    r = rig("V1.1=5", "B1.1", "V1.1, W0.1, ?99.1", "V2.1", "END", "[1.1")
    r.until(30)
    assert r.texts() == []
    r.type("V1.1=0")
    assert r.texts() == []          # the bank goes on in a kernel event, at this instant
    r.kernel.run(until=r.kernel.now)
    assert r.printed == [(seconds(30), "Ux.1=8"), (seconds(30), "V2.1=0")]


def test_w_with_a_ladder_changing_the_condition() -> None:
    r = rig("K63.1=10", "V1.1=0", "V2.1=1", "V3.1=50", "L1.1", "V1.1=V1.1+V2.1;", "END",
            "B1.1", "V3.1>V1.1, W0.1, V1.1", "END", "[L1.1", "[1.1")
    r.until(1)
    assert r.texts() == ["V1.1=50"]   # released by the 50th scan, at 0.49 s
    assert r.times("V1.1=50") == [seconds(0.49)]


def test_t0_does_nothing_and_t_waits_exactly() -> None:
    r = rig("T1.1=250", "B1.1", "T0.1", "V1.1", "T1.1", "V2.1", "END", "[1.1")
    r.until(1)
    (t1,), (t2,) = r.times("V1.1=0"), r.times("V2.1=0")
    assert t2 - t1 == 250 * MS + 250_000   # T1, after the V1 line's one step
    assert t1 == 250_000                   # T0 line: one step


def test_4_3_1_line_waits_for_every_motor_it_moved() -> None:
    r = rig("S1.1=100", "P1.1=1000", "S1.2=10", "P1.2=1000", "B1.1",
            "S1.1, P1.1, S1.2, P1.2", "V1.1", "END", "[1.1", motors=2)
    r.until(3)
    (done2,) = r.times("Ux.2=8")
    assert r.times("V1.1=0") == [done2]
    assert r.times("Ux.1=8")[0] < done2


def test_pause_and_resume_keep_the_remaining_waypoints() -> None:
    """] after passing P1 of a merge line: [ goes on to P2, not back to P1 (2.1.2 "[")."""
    r = rig("S1.1=100", "A1.1=100", "P1.1=5000", "P2.1=10000",
            "B1.1", "S1.1, A1.1, P1.1, P2.1", "END")
    trace = record(r.chain)
    r.type("[1.1")
    r.until(0.7)                 # past P1 (at about 0.55 s)
    r.type("]")
    r.until(1.5)
    stopped = trace.sample(1, seconds(1.5)).command
    assert 5000 < stopped < 10000
    r.type("[")
    r.until(3)
    commands = [trace.sample(1, t).command for t in range(seconds(1.5), seconds(3), MS)]
    assert min(commands) >= stopped - 1e-6 and commands[-1] == 10000


def test_a_free_motor_does_not_hang_a_line() -> None:
    r = rig("S.1=100", "P1.1=100000", "B1.1", "P1.1", "V1.1", "END", "[1.1")
    r.until(0.2)
    r.type(").1")
    r.until(0.3)
    assert r.texts() == ["V1.1=0"]


def test_pause_inside_the_bank_and_resume_after_it() -> None:
    r = rig("B1.1", "V1.1", "]", "V2.1", "END", "[1.1")
    r.until(1)
    assert r.texts() == ["V1.1=0"] and r.motor().program.state == "paused"
    r.type("[")
    r.until(2)
    assert r.texts() == ["V1.1=0", "V2.1=0"]


def test_estop_inside_the_bank_and_release() -> None:
    r = rig("B1.1", "T0.1, *, V3.1", "V2.1", "END", "[1.1")
    r.until(1)
    assert r.texts() == ["Ux.1=512"] and r.motor().program.state == "estop"
    r.type("*1")
    r.until(2)
    assert r.texts()[-1] == "V2.1=0"


def test_2_1_2_estop_twice_stops_the_bank_and_bracket_runs_it_from_the_beginning() -> None:
    """2.1.2 "*": "Program Bank stops when this command is transmitted twice, and Program
    Bank operates from the beginning with command [ after canceling the emergency stop
    by command *1" (the motor audit's example: moves to 2000, 0, 1000 at S=10)."""
    r = rig("S1.1=10", "A1.1=100", "P1.1=2000", "P2.1=0", "P3.1=1000",
            "B1.1", "S1.1, A1.1, P1.1", "P2.1", "P3.1", "END", "[1.1")
    r.until(0.5)
    r.type("*", "*")
    r.until(0.6)
    assert r.motor().program.state == "idle"
    stopped = r.motor().position()
    r.type("[")                       # still in emergency stop: nothing moves
    r.until(1.0)
    assert r.motor().program.state == "idle" and r.motor().position() == stopped
    r.type("*1")                      # released: the stopped bank stays stopped ...
    r.until(1.5)
    assert r.motor().program.state == "idle" and r.motor().position() == stopped
    r.type("[")                       # ... until [ runs it from its first line
    r.until(2.5)
    assert r.motor().program.state == "running"
    assert r.motor().axis.target() == 2000 and r.motor().position() > stopped


def test_2_1_2_pause_twice_terminates_and_bracket_does_not_resume() -> None:
    """2.1.2 "]": "When this command is entered twice, Program Bank is terminated and
    cannot be resumed" (unlike ``*`` twice)."""
    r = rig("S1.1=10", "A1.1=100", "P1.1=2000", "B1.1", "S1.1, A1.1, P1.1", "END", "[1.1")
    r.until(0.5)
    r.type("]", "]")
    r.until(1.0)
    stopped = r.motor().position()
    r.type("[")
    r.until(2.0)
    assert r.motor().program.state == "idle" and r.motor().position() == stopped


def test_queries_from_a_bank_are_bank_replies() -> None:
    r = rig("B1.1", "?96.1", "END")
    seen = []
    r.chain.subscribe(lambda e: seen.append((e.origin, e.kind, e.text)))
    r.type("[1.1")
    r.until(1)
    assert seen == [("bank", "reply", "Px.1=0")]


def test_y_series_on_one_motor_completes_each_motion() -> None:
    r = rig("S.1=100", "P1.1=2000", "P2.1=0", "B1.1", "Y1.1", "Y2.1", "V1.1", "END", "[1.1")
    r.until(2)
    first, second = r.times("Ux.1=8")
    assert r.times("V1.1=0") == [first]   # line 2 waited for Y1.1; line 3 not for Y2.1
    assert second > first + seconds(0.2)


def test_ch3_k55_the_next_bank_line_starts_at_in_position(make_chain: ChainFactory) -> None:
    # K55: "When the range is set to small, In-Position may not be detected and can not
    # execute the next step in a program": the next step follows in-position
    chain = make_chain(setup=["K23.1=17, K55.1=100, S1.1=10, A1.1=10, P1.1=10000, P2.1=0",
                              "B1.1", "S1.1, A1.1, P1.1", "?96.1", "END"])
    events = collect_events(chain)
    chain.execute("[1.1")
    end_of_command = chain.motors[1].axis.profile.end_ns
    chain.kernel.run(until=seconds(12))
    at = next(e.time for e in events if e.text == "Ux.1=8")
    px = next(e for e in events if e.text.startswith("Px.1="))
    assert px.time == at < end_of_command
    assert 9900 <= int(px.text.split("=")[1]) < 10000


def test_ch3_k55_a_path_through_its_target_is_not_in_position_on_the_way(
        make_chain: ChainFactory) -> None:
    # only the final approach counts: a merge out to 10000 and back to 0 from 0 is not
    # in position at its start, though it starts within K55 of its target
    chain = make_chain(setup=["K23.1=1, S1.1=100, A1.1=100, P1.1=3000, P2.1=0", "B1.1",
                              "S1.1, A1.1, P1.1, P2.1", "END"])
    statuses = collect_events(chain, ["status"])
    chain.execute("[1.1")
    chain.kernel.run(until=seconds(0.1))
    assert chain.execute("?99.1") == ["Ux.1=0"]
    chain.kernel.run(until=seconds(3))
    assert [e.text for e in statuses] == ["Ux.1=8"]
    assert abs(chain.motors[1].position()) <= 5


def test_2_2_1_v_alone_in_a_bank_displays_the_state_value(make_chain: ChainFactory) -> None:
    # 2.2.1 / 2.2.2 "V": "When this command is used alone, it displays the specified
    # variable data. This is used for a message sent to a host."
    chain = make_chain(setup=['K23.1=17', 'V4.1="Px"', "S.1=10", "A.1=10", "P.1=1234"])
    chain.execute("^.1")
    chain.kernel.run(until=seconds(3))
    for line in ("B1.1", "V4.1", "V5.1=V4.1", "V5.1", "END"):
        chain.execute(line)
    said = collect_events(chain, ["status", "alarm", "message", "reply"])
    chain.execute("[1.1")
    chain.kernel.run(until=seconds(4))
    assert [e.text for e in said] == ["V4.1=1234", "V5.1=1234"]
    assert chain.execute("V4.1") == ['V4.1="Px"']         # direct mode: what was assigned
