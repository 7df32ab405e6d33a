"""Canonical CML printing (coolmuscle.cml.formatter) and the parse/format round trip."""

from __future__ import annotations

import pytest
from hypothesis import given, settings

from cml_support import corpus_lines, expressions, lines, simple_statements
from coolmuscle.cml import format_expr, format_line, format_statement, parse
from coolmuscle.cml.ast import (
    Alloc,
    Assign,
    BankBegin,
    BankEnd,
    BinOp,
    Branch,
    ClearBanks,
    Compare,
    Exec,
    Func,
    Input,
    Line,
    Logic,
    Not,
    Num,
    Output,
    Query,
    Ref,
    Reg,
    StartBank,
    StopBank,
    Str,
)


def canonical(text: str) -> list[str]:
    return [format_line(line) for line in parse(text)]


# ------------------------------------------------------------ manual readback

def test_6_6_program_bank_listing() -> None:
    """?1.1 -> "S1.1, A1.1, P1.1" (cml-users-guide.txt 6.6)."""
    assert canonical("s1.1 ,a1.1,  P1.1") == ["S1.1, A1.1, P1.1"]


def test_6_6_ladder_bank_listing() -> None:
    """?L1.1 -> "I1.1&&I2.1, O1.1, O2.1" (6.6)."""
    assert canonical("I1.1 && I2.1, O1.1, O2.1") == ["I1.1&&I2.1, O1.1, O2.1"]
    assert canonical("I3.1 || I4.1, O3.1, O4.1") == ["I3.1||I4.1, O3.1, O4.1"]


def test_2_2_2_colon_branch_readback() -> None:
    assert canonical("V1.1 > V2.1, ?99.1: O1.1, ?96.1: F1.1") == [
        "V1.1>V2.1, ?99.1:O1.1, ?96.1:F1.1"]


def test_6_8_not_prints_double_bang() -> None:
    assert canonical("I2.1 && I4.1 && !(I3.1), O1.1, F1.1") == [
        "I2.1&&I4.1&&!!(I3.1), O1.1, F1.1"]


def test_operators_without_spaces() -> None:
    assert canonical("V1.1 = V1.1 + V2.1") == ["V1.1=V1.1+V2.1"]
    assert canonical("P1.1=P2.1 / V1.1") == ["P1.1=P2.1/V1.1"]
    assert canonical("v1 >= v2 + v3, ?99, T0") == ["V1>=V2+V3, ?99, T0"]


def test_upper_case_and_end() -> None:
    assert canonical("end.1") == ["END.1"]
    assert canonical("End") == ["END"]
    assert canonical("p=1000000000") == ["P=1000000000"]
    assert canonical("cl2.1, jl3") == ["CL2.1, JL3"]


def test_index_and_motor_only_when_present() -> None:
    assert format_expr(Reg("P", None, 1)) == "P.1"
    assert format_expr(Reg("P", 0, 1)) == "P0.1"
    assert format_expr(Reg("P", 0, None)) == "P0"
    assert format_expr(Reg("V")) == "V"
    assert format_statement(Query()) == "?"
    assert format_statement(Query(motor=1)) == "?.1"
    assert format_statement(Query(3, "L", 1)) == "?L3.1"
    assert format_statement(StartBank("B")) == "["
    assert format_statement(StartBank("LM", 1)) == "[LM1"
    assert format_statement(StopBank("L", 1)) == "]L.1"


def test_strings_in_double_quotes() -> None:
    assert format_statement(Assign(Reg("V", 1, 1), "=", Str("Px"))) == 'V1.1="Px"'
    assert canonical('V3="Dx"      /target position') == ['V3="Dx"']


def test_joined_line_ends_with_semicolon() -> None:
    assert canonical("S2.1, A2.1, P2.1; S3.1, P3.1") == ["S2.1, A2.1, P2.1;", "S3.1, P3.1"]
    assert canonical("V2.1>V3.1; V2.1=V3.1, T0.1") == ["V2.1>V3.1;", "V2.1=V3.1, T0.1"]


def test_execution_commands() -> None:
    ops = {"go": "^", "origin": "|", "go_origin": "|1", "set_origin": "|2",
           "enable": "(", "free": ")", "pause": "]", "pause_motor": "]1",
           "stop_after_line": "}", "estop": "*", "estop_release": "*1",
           "next_line": ">", "prev_line": "<", "save": "$"}
    for op, text in ops.items():
        assert format_statement(Exec(op)) == text  # type: ignore[arg-type]
        assert format_statement(Exec(op, 3)) == text + ".3"  # type: ignore[arg-type]


def test_2_2_3_go_shorthand_prints_with_dot() -> None:
    """``^1`` (2.2.3 operation example) is ``^.1``."""
    assert canonical("^1") == ["^.1"]


def test_other_statements() -> None:
    assert format_statement(Alloc("P", 300)) == "\\P300"
    assert canonical("¥N200") == ["\\N200"]
    assert format_statement(ClearBanks(True, 1)) == "L100.1"
    assert format_statement(BankEnd()) == "END"
    assert format_statement(Ref(Reg("R", 1, 1), "-")) == "R1.1-"
    assert canonical("X.1-, x3.1, w0, #2.1, @.1+, y2.1, O.4=52481") == [
        "X.1-, X3.1, W0, #2.1, @.1+, Y2.1, O.4=52481"]


# ----------------------------------------------------- trees that cannot print

@pytest.mark.parametrize("expr", [
    BinOp("*", BinOp("+", Num(1), Num(2)), Num(3)),        # (1+2)*3
    BinOp("-", Num(1), BinOp("-", Num(2), Num(3))),        # 1-(2-3)
    Compare(">", Compare(">", Num(1), Num(2)), Num(3)),    # chained comparison
    Compare(">", Logic("&&", Input(1), Input(2)), Num(3)),
    Logic("&&", Input(1), Logic("||", Input(2), Input(3))),
    Logic("&&", Not(Input(1)), Input(2)),                  # 6.8 incorrect example 1
    Logic("&&", Input(1), Not(Not(Input(2)))),             # multiple Not
    Func("U1", Not(Input(1))),                             # Not followed by ')'
    Str('say "hi"'),
    Str("caf\u00e9"),
])
def test_unprintable_expression_raises(expr: object) -> None:
    with pytest.raises(ValueError):
        format_expr(expr)  # type: ignore[arg-type]


@pytest.mark.parametrize("line", [
    Line((BankBegin(False, 100),)),                               # reads as B100 = clear
    Line((Ref(Reg("V", 1)), Ref(Reg("P", 1)))),                   # reads as a branch
    Line((Branch(Input(1), (Output(True, 1),)), Ref(Reg("P", 1)))),
    Line((Branch(Input(1), ()),)),                                # no action, not joined
    Line((Branch(Reg("V", 1), ()),), joined=True),                # reads as a Ref
    Line((Branch(Input(1), (), (Output(True, 1),)),), joined=True),
    Line((Branch(Num(1), (Output(True, 1),)),)),                  # not a condition
    Line((Branch(Input(1), (Branch(Input(2), (Exec("go"),)),)),)),
    Line((Exec("fly"),)),  # type: ignore[arg-type]
])
def test_unprintable_line_raises(line: Line) -> None:
    with pytest.raises(ValueError):
        format_line(line)


def test_empty_line_prints_empty() -> None:
    assert format_line(Line(())) == ""


# ------------------------------------------------------------------ round trip

@settings(max_examples=400, deadline=None)
@given(lines())
def test_round_trip_parse_of_format_is_identity(line: Line) -> None:
    """parse(format_line(l)) == [l] for every parser-shaped Line."""
    assert parse(format_line(line)) == [line]


@settings(max_examples=200, deadline=None)
@given(simple_statements)
def test_round_trip_single_statement(stmt: object) -> None:
    text = format_statement(stmt)  # type: ignore[arg-type]
    assert [line.statements for line in parse(text)] == [(stmt,)]


@settings(max_examples=200, deadline=None)
@given(expressions)
def test_round_trip_expression_as_assignment(expr: object) -> None:
    text = "V1.1=" + format_expr(expr)  # type: ignore[arg-type]
    expected = Assign(Reg("V", 1, 1), "=", expr)  # type: ignore[arg-type]
    assert parse(text)[0].statements == (expected,)


def test_format_is_idempotent_on_manual_corpus() -> None:
    for text in corpus_lines("ok", "cond"):
        for line in parse(text):
            once = format_line(line)
            assert canonical(once) == [once], text
