"""Bank definition and storage: upload, checks, limits, readback, saving.

cml-users-guide.txt 2.2.2, 2.2.3, 6.3-6.6, ch. 3 K23; cm-banks-rt3.txt 1.1, 1.2, 2.3,
3.2-3.4.  Choices: docs/fidelity.md "Banks and ladder".
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bank_support import rig
from fixtures import ChainFactory


def test_2_2_2_lines_of_a_bank_are_stored_not_executed() -> None:
    r = rig("S1.1=5", "B1.1", "S1.1=7", "P1.1", "?96.1", "END")
    assert r.texts() == ["[End of Bank]"]
    assert r.chain.get_register(1, "S", 1) == 5
    r.type("?1.1")
    assert r.texts()[1:] == ["S1.1=7", "P1.1", "?96.1"]


def test_omitted_motor_ids_are_the_banks() -> None:
    r = rig("B1.2", "S1, A1, P1, P2.1", "I3, V1=V2+I1.1, T0", "C2", "END", motors=2)
    r.clear()
    r.type("?1.2")
    assert r.texts() == ["S1.2, A1.2, P1.2, P2.1", "I3.2, V1.2=V2.2+I1.1, T0.2", "C2.2"]
    r.clear()
    r.type("?1.1")   # motor 1 has no bank 1
    assert r.texts() == ["error05.1: Program Bank does not exist!!"]


@pytest.mark.parametrize("end", ["END", "END.1", "end.1", "End.1", ""])
def test_2_2_2_a_bank_ends_with_end_or_a_blank_line(end: str) -> None:
    r = rig("B3.1", "T1.1", end, "?3.1")
    assert r.texts() == ["[End of Bank]", "T1.1"]


def test_comment_lines_are_not_stored_and_do_not_end_a_bank() -> None:
    r = rig("B3.1", "// comment", "T1.1 // timer", "T2.1", "END", "?3.1")
    assert r.texts() == ["[End of Bank]", "T1.1", "T2.1"]


def test_joined_lines_read_back_one_line_each_with_semicolon() -> None:
    r = rig("B2.1", "S2.1, A2.1, P2.1; S3.1, P3.1", "END", "?2.1")
    assert r.texts()[1:] == ["S2.1, A2.1, P2.1;", "S3.1, P3.1"]


def test_k23_without_16_is_silent_but_loading_still_stops() -> None:
    r = rig("B1.1", "T1.1", "P2.1,,", "T2.1", "END", "?1.1", k23=9)
    assert r.texts() == ["T1.1"]


def test_redefining_a_bank_replaces_it() -> None:
    r = rig("B1.1", "T1.1", "T2.1", "END", "B1.1", "T3.1", "END")
    r.clear()
    r.type("?1.1")
    assert r.texts() == ["T3.1"]


def test_rt3_3_3_syntax_error_stops_loading_at_that_line() -> None:
    r = rig("B1.1", "S1.1, A1.1, P1.1", "P2.1 P3.1", "P4.1", "END", "?1000")
    assert r.texts() == ["error01.1: syntax error!!", "B1.1", "S1.1, A1.1, P1.1", "END.1",
                         "Commands.1: program 3, ladder 0, total 3/500"]


def test_a_physical_line_loads_whole_or_not_at_all() -> None:
    r = rig("B1.1", "T1.1; J2.1, T2.1", "END", "?1.1")
    assert r.texts() == ["error04.1: J can not be followed by T"]


def test_rt3_3_3_2_forty_characters_between_commas() -> None:
    forty = "V10.1=V2.1+V3.1+V4.1+V5.1+V6.1+V7.1+V8.1"
    assert len(forty) == 40
    r = rig("B1.1", f"{forty}, T1.1", f"T1.1,  {forty}+V9", "END", "?1.1")
    assert r.texts() == ["error01.1: syntax error!!", f"{forty}, T1.1"]


@pytest.mark.parametrize(("line", "program", "ladder"), [
    ("^.1", "^", "^"), ("]1.1", "]1", "]1"), ("}.1", "}", "}"), (">.1", ">", ">"),
    ("<.1", "<", "<"), ("$.1", "$", "$"), ("[L2.1", "[L", None), ("]L.1", "]L", None),
    ("[LM2.1", "[LM", None), ("X3.1", None, "X"), ("X.1-", None, "X-"), ("C2.1", None, "C"),
    ("J2.1", None, "J"), ("CL2.1", "CL", None), ("JL2.1", "JL", None), ("Y1.1", None, "Y"),
    ("Q1.1", None, "Q"), ("?L1.1", "?L", "?L"), ("?A.1", "?A", "?A"), ("?1000.1", "?1000",
     "?1000"), ("?999.1", "?999", "?999"), ("B100", "B100", "B100"), ("L2.1", "L", "L"),
    ("\\P300", "\\", "\\"), ("]", None, None), ("[2.1", None, None), ("*", None, None),
    ("*1", None, None), ("O1.1", None, None), ("?99.1", None, None), ("?3.1", None, None),
    ("|.1", None, None), ("#2.1", None, None), ("(.1", None, None), ("V1.1", None, None),
])
def test_6_5_commands_not_allowed_in_banks_give_error03(
        line: str, program: str | None, ladder: str | None) -> None:
    for head, refused in (("B1.1", program), ("L1.1", ladder)):
        r = rig(head, line, "END")
        expected = "[End of Bank]" if refused is None else \
            f"error03.1: {refused} is not allowed in bank.1"
        assert r.texts() == [expected], (head, line)


def test_rt3_lets_logic_banks_run_go() -> None:
    """RT3 7.1-7.3 run "^.1" from logic banks; CM2 6.5 marks "^" as × in banks."""
    assert rig("L1.1", "^.1", "END", firmware="rt3").texts() == ["[End of Bank]"]


@pytest.mark.parametrize(("line", "xx", "dd"), [
    ("J2.1, T1.1", "J", "T"), ("C2.1, P1.1", "C", "P"), ("T1.1, X2.1", "T", "X"),
    ("X2.1, P1.1", "X", "P"), ("I1.1, X.1-, T0.1", "I", "X-"),
    ("I1.1, W1.1:O1.1, T0.1", "W", "O"), ("I1.1, T0.1, W1.1", "I", "W"),
    ("P1.1, Y2.1, P3.1", "Y", "P"), ("S1.1, Q2.1, P3.1", "Q", "P"),
    ("Z2.1, Y3.1", "Z", "Y"),
])
def test_error04_command_that_cannot_follow(line: str, xx: str, dd: str) -> None:
    r = rig("B1.1", line, "END")
    assert r.texts() == [f"error04.1: {xx} can not be followed by {dd}"]


def test_motions_of_other_motors_may_follow_y() -> None:
    assert rig("B1.1", "Y1.1, P1.2, Q1.3", "END").texts() == ["[End of Bank]"]


def test_w_outside_a_branch_and_end_with_more_are_syntax_errors() -> None:
    assert rig("B1.1", "W1.1", "END").texts() == ["error01.1: syntax error!!"]
    assert rig("B1.1", "T1.1, END").texts() == ["error01.1: syntax error!!"]


def test_rt3_1_2_numbers_cannot_be_set_in_a_bank() -> None:
    """RT3 1.2: "CORRECT V1.1=100 B1.1 A1.1=V1.1 END.1 / INCORRECT B1.1 A1.1=100"."""
    assert rig("B1.1", "A1.1=V1.1", "END", firmware="rt3").texts() == ["[End of Bank]"]
    assert rig("B1.1", "A1.1=100", "END", firmware="rt3").texts() == [
        "error01.1: syntax error!!"]
    assert rig("B1.1", "A1.1=100", "END").texts() == ["[End of Bank]"]   # CM2: silent


def test_rt3_1_1_no_comments_inside_banks() -> None:
    r = rig("L1.1", "V1=V2+V3 /sum", "END", firmware="rt3")
    assert r.texts() == ["error01.1: syntax error!!"]


def test_rt3_3_4_step_examples() -> None:
    """"1 step: L1.1 END.1", "7 steps: L1.1 V1==P1,S0,CL2 END.1 L2.1 M0 END.1",
    "4 steps: L1.1 V1=V2+V3 END.1"."""
    r = rig("L1.1", "END.1", firmware="rt3")
    assert r.motor().banks.used() == 1
    r = rig("L1.1", "V1==P1,S0,CL2", "END.1", "L2.1", "M0", "END.1", firmware="rt3")
    assert r.motor().banks.used() == 7
    r = rig("L1.1", "V1=V2+V3", "END.1", firmware="rt3")
    assert r.motor().banks.used() == 4
    r = rig("L1", "V1=V1+V2", "V3=U2(V1)", "END", firmware="rt3")   # RT3 3.6 "6 steps"
    assert r.motor().banks.used() == 6


def test_rt3_200_steps_are_shared_by_all_banks() -> None:
    lines = [f"V{n % 15 + 1}=V{n % 15 + 1}+V{(n + 1) % 15 + 1}" for n in range(33)]
    r = rig("B1.1", *lines, "END", firmware="rt3")          # 1 + 33 x 3 = 100 steps
    assert r.motor().banks.used() == 100
    r.type("L1.1", *lines, "END")                           # 100 more: exactly 200
    assert r.texts() == ["[End of Bank]", "[End of Bank]"]
    r.type("L2.1", "T1.1", "END")                           # no room for its header
    assert r.texts()[-1] == "error02.1: too many steps!!"
    assert r.motor().banks.get(True, 2) is None
    r.type("B1.1", "T1.1", "END")                           # redefining frees bank 1
    assert r.motor().banks.used() == 102
    r.clear()
    r.type("L2.1", *lines[:32], "T1.1", "END")              # 102 + 1 + 96 = 199, 200
    r.type("L3.1")                                          # 201: refused
    assert r.texts() == ["[End of Bank]", "error02.1: too many steps!!"]
    r.type("END")


def test_2_2_2_500_commands_per_motor_on_cm2() -> None:
    line = ", ".join(["T0.1"] * 10)
    r = rig("B1.1", *[line] * 40, "END", "L1.1", *[line] * 10, "END")
    assert r.texts() == ["[End of Bank]", "[End of Bank]"]
    assert r.motor().banks.used() == 500
    r.type("B2.1", "T0.1", "END")
    assert r.texts()[-1] == "error02.1: too many steps!!"
    r.clear()
    r.type("?1000.1")
    assert r.texts()[-1] == "Commands.1: program 400, ladder 100, total 500/500"


def test_bank_numbers_1_to_30() -> None:
    r = rig("B31.1", "?96.1", "END", "L0.1", "?96.1", "END", "B30.1", "END")
    assert r.texts() == ["error00.1: Out Of Range!!", "error00.1: Out Of Range!!",
                         "[End of Bank]"]


def test_a_bank_for_a_motor_not_on_the_chain_is_swallowed() -> None:
    r = rig("B1.5", "?96.1", "END", "?96.1")
    assert r.texts() == ["Px.1=0"]


def test_bank_header_stands_alone() -> None:
    r = rig("B1.1, T1.1", "T2.1", "?1.1")
    assert r.texts() == ["error01.1: syntax error!!", "T2.1=0",
                         "error05.1: Program Bank does not exist!!"]


def test_a_bank_typed_on_the_host_line_ignores_api_lines() -> None:
    r = rig("B1.1", "T1.1")
    assert r.chain.execute("?96.1") == ["Px.1=0"]
    r.type("T2.1", "END", "?1.1")
    assert r.texts()[-2:] == ["T1.1", "T2.1"]


def test_b100_l100_clear_and_stop_banks() -> None:
    r = rig("K63.1=1", "L1.1", "V1=V1+V2;", "END", "B1.1", "X0.1", "T1.1", "END",
            "T1.1=10", "V2.1=1", "[L1.1", "[1.1")
    r.wait(0.05)
    r.type("B100")
    assert r.motor().program.state == "idle" and r.motor().ladder.state == "running"
    r.type("L100")
    assert r.motor().ladder.state == "idle"
    r.clear()
    r.type("?1000")
    assert r.texts() == ["Commands.1: program 0, ladder 0, total 0/500"]


def test_6_6_missing_bank_queries() -> None:
    r = rig("?4.1", "?L4.1", "?31.1", "?L31.1")
    assert r.texts() == ["error05.1: Program Bank does not exist!!",
                         "error06.1: Ladder Bank does not exist!!"]


def test_2_1_2_banks_are_saved_with_dollar_and_restored_at_power_up(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    first = make_chain(state_dir=tmp_path)
    for line in ("B1.1", "S1.1, A1.1, P1.1; S2.1, P2.1", "T1.1", "END",
                 "L2.1", 'V1.1>V2.1, S.1=S1.1, S.1=S2.1', "END", "$.1"):
        first.execute(line)
    first.execute("B3.1")
    first.execute("T3.1")
    first.execute("END")       # not saved
    first.close()
    second = make_chain(state_dir=tmp_path)
    assert second.execute("?1.1") == ["S1.1, A1.1, P1.1;", "S2.1, P2.1", "T1.1"]
    assert second.execute("?L2.1") == ["V1.1>V2.1, S.1=S1.1, S.1=S2.1"]
    assert second.execute("?3.1") == []   # error05 not printed with K23=1
    assert second.motors[1].banks.get(False, 3) is None
    second.close()


def test_unsaved_banks_are_lost_at_power_off(tmp_path: Path, make_chain: ChainFactory) -> None:
    first = make_chain(state_dir=tmp_path)
    for line in ("B1.1", "T1.1", "END", "K23.1=17"):
        first.execute(line)
    first.close()
    second = make_chain(state_dir=tmp_path)
    assert second.execute("?1000.1") == ["Commands.1: program 0, ladder 0, total 0/500"]
    second.close()
