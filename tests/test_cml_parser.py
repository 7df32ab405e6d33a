"""The CML parser (coolmuscle.cml.parser): statement forms, errors, manual corpus, oracle."""

from __future__ import annotations

import copy
import dataclasses
import importlib.util
import pickle
import sys
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings

from cml_support import Example, corpus, lines
from coolmuscle.cml import format_line, parse
from coolmuscle.cml.ast import (
    Alloc,
    Assign,
    BankBegin,
    BankEnd,
    BinOp,
    Branch,
    Call,
    Capture,
    ClearBanks,
    Compare,
    Exec,
    Func,
    Input,
    Interp,
    Line,
    Logic,
    Loop,
    LoopEnd,
    Move,
    Not,
    Num,
    Output,
    OutputWord,
    Query,
    Ref,
    Reg,
    StartBank,
    StopBank,
    Str,
    Wait,
)
from coolmuscle.errors import CmlSyntaxError


def one(text: str) -> Any:
    """The only statement of a one-statement line."""
    (line,) = parse(text)
    (stmt,) = line.statements
    return stmt


def stmts(text: str) -> tuple[Any, ...]:
    (line,) = parse(text)
    return line.statements


def error(text: str) -> CmlSyntaxError:
    with pytest.raises(CmlSyntaxError) as info:
        parse(text)
    return info.value


# ---------------------------------------------------------------- basics

def test_blank_and_comment_only_lines_are_empty() -> None:
    for text in ["", "   ", "\t", "// Comments here", "  // x", "/bank 1 looks at input 3",
                 "/If it is equal to the", "/ 5 apples"]:
        assert parse(text) == [], text


def test_1_1_case_insensitive() -> None:
    assert one("end.1") == one("End.1") == one("END.1") == BankEnd(1)
    assert one("v1") == Ref(Reg("V", 1))
    assert one("p=1000000000") == Assign(Reg("P"), "=", Num(1000000000))
    assert one("cl2.1") == Call("CL", 2, 1)
    assert one("?l3") == Query(3, "L")


def test_blanks_between_tokens_not_inside() -> None:
    assert one("P2.1 =  P3.1 +V2.1") == one("P2.1=P3.1+V2.1")
    assert error("P 1.1=5").position == 2
    assert error("P1 .1=5").position == 3
    assert error("? 96").position == 2
    assert error("P2.1 +").position == 6  # a modifier touches its register


def test_source_is_the_text_without_comment() -> None:
    (line,) = parse("  P1.1=1000 /end point")
    assert line.source == "P1.1=1000"
    (line,) = parse("B1.1//comment")
    assert line.source == "B1.1" and line.statements == (BankBegin(False, 1, 1),)


# ----------------------------------------------------- data commands (2.1.1)

def test_2_1_1_direct_data() -> None:
    assert one("P.1=10000") == Assign(Reg("P", None, 1), "=", Num(10000))
    assert one("P.1=-5000") == Assign(Reg("P", None, 1), "=", Num(-5000))
    assert one("P.1+=100") == Assign(Reg("P", None, 1), "+=", Num(100))
    assert one("P.1-=200") == Assign(Reg("P", None, 1), "-=", Num(200))
    assert one("P0.1=1") == Assign(Reg("P", 0, 1), "=", Num(1))
    assert stmts("N.1=50, N.2=30") == (Assign(Reg("N", None, 1), "=", Num(50)),
                                        Assign(Reg("N", None, 2), "=", Num(30)))


def test_registers_with_index_and_motor() -> None:
    for kind in "PSAMTVNRKH":
        assert one(f"{kind}7.3=1").target == Reg(kind, 7, 3)
    assert one("K23.1=16") == Assign(Reg("K", 23, 1), "=", Num(16))
    assert one("H0") == Ref(Reg("H", 0))
    assert one("S0=S1") == Assign(Reg("S", 0), "=", Reg("S", 1))
    assert one("P01.1=+5") == Assign(Reg("P", 1, 1), "=", Num(5))


def test_2_2_1_variables() -> None:
    assert one('V3.1="abcd"') == Assign(Reg("V", 3, 1), "=", Str("abcd"))
    assert one('V4.1="Px"') == Assign(Reg("V", 4, 1), "=", Str("Px"))
    assert one('V1=""') == Assign(Reg("V", 1), "=", Str(""))
    assert one("V3=I3") == Assign(Reg("V", 3), "=", Input(3))
    assert one("V1 = I4.1 && I3.2") == Assign(Reg("V", 1), "=",
                                              Logic("&&", Input(4, 1), Input(3, 2)))
    assert one("V1 = !(I3.2)") == Assign(Reg("V", 1), "=", Not(Input(3, 2)))
    assert one("S0.1=V1.1/V2.1") == Assign(Reg("S", 0, 1), "=",
                                          BinOp("/", Reg("V", 1, 1), Reg("V", 2, 1)))


def test_strings_keep_case_and_hold_punctuation() -> None:
    assert one('V1="a;/,"') == Assign(Reg("V", 1), "=", Str("a;/,"))
    assert error('V1="abc').position == 3
    assert error('V1="\u00e9"').position == 4


# ------------------------------------------------------- program commands

def test_2_2_2_refs_and_modifiers() -> None:
    assert one("P2.1+") == Ref(Reg("P", 2, 1), "+")
    assert one("P1.3-") == Ref(Reg("P", 1, 3), "-")
    assert stmts("R1.1-,R1.2-") == (Ref(Reg("R", 1, 1), "-"), Ref(Reg("R", 1, 2), "-"))
    assert stmts("S1.1, A1.1, P1.1") == (Ref(Reg("S", 1, 1)), Ref(Reg("A", 1, 1)),
                                         Ref(Reg("P", 1, 1)))
    assert one("T1.1") == Ref(Reg("T", 1, 1))
    assert one("V2.1") == Ref(Reg("V", 2, 1))  # alone: display, not a branch


def test_2_2_2_moves_and_interpolation() -> None:
    assert one("Y2.1") == Move("Y", 2, 1)
    assert one("Q10.1") == Move("Q", 10, 1)
    assert one("Z1.1-") == Move("Z", 1, 1, "-")
    assert stmts("@.1+, @.2+") == (Interp(None, 1, "+"), Interp(None, 2, "+"))
    assert stmts("@3.1-, @4.2-") == (Interp(3, 1, "-"), Interp(4, 2, "-"))
    assert one("@2.2") == Interp(2, 2)


def test_2_2_2_bank_structure() -> None:
    assert one("B2.1") == BankBegin(False, 2, 1)
    assert one("L2.1") == BankBegin(True, 2, 1)
    assert one("B100") == ClearBanks(False)
    assert one("L100") == ClearBanks(True)
    assert one("END") == BankEnd()
    assert one("C2.1") == Call("C", 2, 1)
    assert one("J2") == Call("J", 2)
    assert one("JL2.1") == Call("JL", 2, 1)
    assert one("X3.1") == Loop(3, 1)
    assert one("X0.1") == Loop(0, 1)
    assert one("X255") == Loop(255)
    assert one("X.1-") == LoopEnd(1)
    assert one("X-") == LoopEnd()
    assert one("W0") == Wait(0)
    assert error("X256").position == 1
    assert error("X").position == 1
    assert error("END1").position == 3


# ----------------------------------------------------- execution (2.1.2, 6.5)

@pytest.mark.parametrize(("text", "stmt"), [
    ("^.1", Exec("go", 1)), ("^", Exec("go")), ("|.1", Exec("origin", 1)),
    ("|", Exec("origin")), ("|1.2", Exec("go_origin", 2)), ("|2.3", Exec("set_origin", 3)),
    ("(.1", Exec("enable", 1)), (").1", Exec("free", 1)), ("]", Exec("pause")),
    ("].1", Exec("pause", 1)), ("]1.3", Exec("pause_motor", 3)),
    ("}.1", Exec("stop_after_line", 1)), ("*", Exec("estop")),
    ("*1", Exec("estop_release")), (">.2", Exec("next_line", 2)),
    ("<.2", Exec("prev_line", 2)), ("$.1", Exec("save", 1)),
    ("O2.1", Output(True, 2, 1)), ("F2.1", Output(False, 2, 1)), ("#2.1", Capture(2, 1)),
    ("[1.2", StartBank("B", 1, 2)), ("[", StartBank("B")), ("[.1", StartBank("B", None, 1)),
    ("[L2.1", StartBank("L", 2, 1)), ("[L", StartBank("L")), ("[LM1", StartBank("LM", 1)),
    ("]L.1", StopBank("L", 1)), ("]LM", StopBank("LM")),
    ("\\P300", Alloc("P", 300)), ("\\N200", Alloc("N", 200)),
    ("\u00a5P300", Alloc("P", 300)),
])
def test_6_5_execution_commands(text: str, stmt: object) -> None:
    assert one(text) == stmt


def test_2_2_3_go_shorthand() -> None:
    """``^1`` in the 2.2.3 operation example is read as ``^.1``."""
    assert one("^1") == Exec("go", 1)
    assert error("^0").position == 1
    assert error("^1.2").position == 2


def test_5_6_7_output_word() -> None:
    assert one("O.4=52481") == OutputWord(Num(52481), 4)
    assert one("O=V1") == OutputWord(Reg("V", 1))
    assert error("O2.1=5").position == 4
    assert error("O.4").position == 3


@pytest.mark.parametrize("text", ["|3", "]2", "*2", "]X", "[X", "#", "\\Q3", "\\P3.1",
                                  "(1", "?K1", "?PX"])
def test_malformed_commands(text: str) -> None:
    error(text)


# ---------------------------------------------------------------- queries

@pytest.mark.parametrize(("text", "stmt"), [
    ("?", Query()), ("?.1", Query(motor=1)), ("?96.1", Query(96, None, 1)),
    ("?3.1", Query(3, None, 1)), ("?1000.1", Query(1000, None, 1)), ("?999", Query(999)),
    ("?90", Query(90)), ("?A.1", Query(None, "A", 1)), ("?S", Query(None, "S")),
    ("?M", Query(None, "M")), ("?T", Query(None, "T")), ("?V", Query(None, "V")),
    ("?P", Query(None, "P")), ("?N", Query(None, "N")), ("?R", Query(None, "R")),
    ("?L3.1", Query(3, "L", 1)),
])
def test_6_6_queries(text: str, stmt: object) -> None:
    assert one(text) == stmt


# ------------------------------------------------------------ expressions

def test_6_7_precedence_and_left_association() -> None:
    v1, v2, v3 = Reg("V", 1), Reg("V", 2), Reg("V", 3)
    assert one("P1=V1+V2*V3").value == BinOp("+", v1, BinOp("*", v2, v3))
    assert one("P1=V1*V2+V3").value == BinOp("+", BinOp("*", v1, v2), v3)
    assert one("P1=V1-V2-V3").value == BinOp("-", BinOp("-", v1, v2), v3)
    assert one("P1=V1/V2/V3").value == BinOp("/", BinOp("/", v1, v2), v3)
    assert one("P1=V1--5").value == BinOp("-", v1, Num(-5))
    assert error("P1=V1- -V2").position == 8


def test_6_7_functions() -> None:
    for n in range(1, 7):
        assert one(f"P1.1=U{n}(V1.1)").value == Func(f"U{n}", Reg("V", 1, 1))
    assert one("P1.1=P2.1+U3(V1.1)").value == BinOp(
        "+", Reg("P", 2, 1), Func("U3", Reg("V", 1, 1)))
    assert error("P1=U7(V1)").position == 3
    assert error("P1=U1.1(V1)").position == 5


def test_6_9_comparisons() -> None:
    for op in ["==", "!=", ">", ">=", "<", "<="]:
        (branch,) = stmts(f"V1.1 {op} V2.1 + V3.1, ?99, ?98")
        assert branch.condition == Compare(
            op, Reg("V", 1, 1), BinOp("+", Reg("V", 2, 1), Reg("V", 3, 1)))
    assert error("V1>V2>V3, ?99").position == 5


def test_logic_is_left_to_right() -> None:
    (branch,) = stmts("I1 || I2 && I3, ?99")
    assert branch.condition == Logic(
        "&&", Logic("||", Input(1), Input(2)), Input(3))


def test_6_8_not_operator_examples() -> None:
    """Correct and incorrect examples of cml-users-guide.txt 6.8."""
    (branch,) = stmts("I2.1 && I4.1 && !(I3.1), O1.1, F1.1")
    assert branch == Branch(
        Logic("&&", Logic("&&", Input(2, 1), Input(4, 1)), Not(Input(3, 1))),
        (Output(True, 1, 1),), (Output(False, 1, 1),))
    first = error("I2.1 && !(I3.1) && I4.1, O1.1, F1.1")
    assert first.position == 16 and "followed by ','" in str(first)
    second = error("I2.1 && !(I3.1) && !(I4.1), O1.1, F1.1")
    assert second.position == 19 and "one Not" in str(second)
    assert one("V1=!!(I3.2)") == one("V1=!(I3.2)")
    assert stmts("!!(I3.2), O1, F1")[0].condition == Not(Input(3, 2))


def test_not_may_repeat_in_separate_statements() -> None:
    assert len(stmts("V1=!!(I1), V2=!(I2)")) == 2
    (branch,) = stmts("!!(I1), V1=!!(I2):V2=!!(I3)")
    assert len(branch.then) == 2
    assert error("V1=!!(!!(I1))").position == 6


# ----------------------------------------------------------------- branches

def test_4_2_2_input_and_variable_branches() -> None:
    assert one("I3.1, ?99.1, ?98.1") == Branch(Input(3, 1), (Query(99, None, 1),),
                                               (Query(98, None, 1),))
    assert one("V1.1, ?99.1, ?98.1") == Branch(Reg("V", 1, 1), (Query(99, None, 1),),
                                               (Query(98, None, 1),))
    assert one("I3.1, W1, ?98.1") == Branch(Input(3, 1), (Wait(1),), (Query(98, None, 1),))
    assert one("V1.1, ?99") == Branch(Reg("V", 1, 1), (Query(99),))


def test_2_2_2_colon_junctions() -> None:
    assert one("V1.1 > V2.1, ?99.1: O1.1, ?96.1: F1.1") == Branch(
        Compare(">", Reg("V", 1, 1), Reg("V", 2, 1)),
        (Query(99, None, 1), Output(True, 1, 1)), (Query(96, None, 1), Output(False, 1, 1)))
    assert one("v1>v2,s0=s1:^:t1,CL2") == Branch(
        Compare(">", Reg("V", 1), Reg("V", 2)),
        (Assign(Reg("S", 0), "=", Reg("S", 1)), Exec("go"), Ref(Reg("T", 1))),
        (Call("CL", 2),))
    assert one("V1>V2,W0,?96:?90").orelse == (Query(96), Query(90))


def test_rt3_any_register_compares() -> None:
    assert one("V1==P1,S0,CL2") == Branch(Compare("==", Reg("V", 1), Reg("P", 1)),
                                          (Ref(Reg("S", 0)),), (Call("CL", 2),))
    assert one("I1==V1,C2.1,C3.1").condition == Compare("==", Input(1), Reg("V", 1))


def test_branch_errors() -> None:
    assert error("V1>V2, ?99, ?98, ?97").position == 15  # more than 3 elements
    assert error("?99, V1>V2").position == 5              # condition not first
    assert error("?99, I1").position == 5
    assert error("P1+V2, ?99").position == 0             # not a condition
    assert error("V1 > V2").position == 7                 # no action, not joined
    assert error("I3.1").position == 4
    assert error("S1, A1: P1").position == 6              # ':' outside a branch


# --------------------------------------------------------------- semicolons

def test_2_2_2_semicolon_splits_lines() -> None:
    assert parse("S2.1, A2.1, P2.1; S3.1, P3.1") == [
        Line((Ref(Reg("S", 2, 1)), Ref(Reg("A", 2, 1)), Ref(Reg("P", 2, 1))), True,
             "S2.1, A2.1, P2.1"),
        Line((Ref(Reg("S", 3, 1)), Ref(Reg("P", 3, 1))), False, "S3.1, P3.1")]
    assert parse("V1=V2+V3;") == [
        Line((Assign(Reg("V", 1), "=", BinOp("+", Reg("V", 2), Reg("V", 3))),), True,
             "V1=V2+V3")]
    assert [line.joined for line in parse("P1;P2;P3; // c")] == [True, True, True]


def test_2_2_3_condition_joined_to_next_line() -> None:
    first, second = parse("V2.1>V3.1; V2.1=V3.1, T0.1")
    assert first == Line((Branch(Compare(">", Reg("V", 2, 1), Reg("V", 3, 1)), ()),), True,
                         "V2.1>V3.1")
    assert second.statements == (Assign(Reg("V", 2, 1), "=", Reg("V", 3, 1)),
                                 Ref(Reg("T", 0, 1)))


def test_empty_segments_are_errors() -> None:
    assert error(";").position == 0
    assert error("P1;;P2").position == 3
    assert error("P1,").position == 3
    assert error(",P1").position == 0


# ----------------------------------------------------------------- comments

def test_rt3_1_1_slash_comment_or_division() -> None:
    assert one("P1.1=1000 /end point") == Assign(Reg("P", 1, 1), "=", Num(1000))
    assert one('V3="Dx"      /target position') == Assign(Reg("V", 3), "=", Str("Dx"))
    assert one("V2=1        /incremental counter") == Assign(Reg("V", 2), "=", Num(1))
    assert one("P1.1=P2.1/V1.1").value == BinOp("/", Reg("P", 2, 1), Reg("V", 1, 1))
    assert one("P1.1=P2.1 / V1.1") == one("P1.1=P2.1/V1.1")
    assert one("P1=V1/-2").value == BinOp("/", Reg("V", 1), Num(-2))
    assert one("P1=V1/P").value == BinOp("/", Reg("V", 1), Reg("P"))
    assert one("P2.1+ /P3 comment") == Ref(Reg("P", 2, 1), "+")
    assert error("S1.1, /V1 is").position == 5  # after ',' a '/' starts a comment
    assert one("P1=V1//V2") == Assign(Reg("P", 1), "=", Reg("V", 1))


# ------------------------------------------------------------ number limits

def test_number_limits() -> None:
    assert one("P1=9999999999").value == Num(9999999999)
    assert one("P1=-1000000000").value == Num(-1000000000)
    assert error("P1=12345678901").position == 3
    assert error("P1=" + "9" * 10000).position == 3
    assert one("P9999=1").target == Reg("P", 9999)
    assert error("P10000=1").position == 1
    assert one("P1.99=1").target == Reg("P", 1, 99)
    assert error("P1.0=1").position == 3
    assert error("P1.100=1").position == 3
    assert error("P1.1=5.1").position == 6


@pytest.mark.parametrize(("text", "position"), [
    ("P1.1=", 5), ("&", 0), ("P1.1=P2.1 Q", 10), ("V1.1=Ix", 5), ("C", 1), ("@2.1*", 4),
    ("V1=-V2", 4), ("U7(V1), ?99", 0), ("P1=1\x00", 4), ("P1=\u0661", 3), ("P1=1.", 4),
    ("P1\r", 2), ("V1=(V2)", 3), ("I, ?99", 1),
])
def test_error_positions(text: str, position: int) -> None:
    assert error(text).position == position


def test_error_is_motor_error_01() -> None:
    err = error("P1.1=")
    assert err.number == 1 and err.motor_line(1) == "error01.1: syntax error!!"
    assert err.text_line == "P1.1=" and isinstance(err, SyntaxError)


# -------------------------------------------------------------- manual corpus

def _corpus_id(ex: Example) -> str:
    return f"{ex.section.split()[0].split('-')[1][:4]} {ex.section.split()[-1]} {ex.line}"


@pytest.mark.parametrize("example", corpus(), ids=_corpus_id)
def test_manual_corpus_example(example: Example) -> None:
    """Every example line of the manuals parses; the wrong ones fail."""
    if example.expect == "fail":
        error(example.text)
        return
    result = parse(example.text)
    for line in result:
        assert [x.statements for x in parse(format_line(line))] == [line.statements]


@settings(max_examples=200, deadline=None)
@given(lines())
def test_trees_pickle_copy_and_stay_frozen(line: Line) -> None:
    """The tree's nodes are frozen dataclasses that pickle, copy and compare by value,
    compiled too (coolmuscle/_accel.py: ast.Frozen)."""
    assert pickle.loads(pickle.dumps(line)) == line
    assert copy.deepcopy(line) == line and copy.copy(line) == line
    assert dataclasses.replace(line) == line and hash(dataclasses.replace(line)) == hash(line)
    with pytest.raises(dataclasses.FrozenInstanceError):
        line.joined = not line.joined  # type: ignore[misc]
    assert not hasattr(line, "__dict__")


def test_2_2_2_typo_equals_query_is_rejected() -> None:
    """``V2.1=?V3.1`` (2.2.2) is a typo of ``V2.1==V3.1`` (2.2.3); it is refused."""
    assert error("V2.1=?V3.1, ?99.1, ?98.1").position == 5


# ------------------------------------------------------------ lark oracle

def _load_lark_cml() -> Any:
    path = Path(__file__).resolve().parents[1] / "bench" / "cml_lark.py"
    spec = importlib.util.spec_from_file_location("cml_lark", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["cml_lark"] = module
    spec.loader.exec_module(module)
    return module.LarkCml()


_LARK = _load_lark_cml()


@settings(max_examples=300, deadline=None)
@given(lines())
def test_lark_grammar_agrees_on_generated_lines(line: Line) -> None:
    """Differential oracle: an independent LALR grammar builds the same trees."""
    text = format_line(line)
    ours = parse(text)
    theirs = _LARK.parse(text)
    assert [(x.statements, x.joined) for x in theirs] == [(x.statements, x.joined)
                                                          for x in ours]


def test_lark_grammar_agrees_on_manual_corpus() -> None:
    for ex in corpus():
        ours = parse(ex.text) if ex.expect != "fail" else []
        if ours:
            theirs = _LARK.parse(ex.text)
            assert [x.statements for x in theirs] == [x.statements for x in ours], ex.text
