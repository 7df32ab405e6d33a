"""Test support for CML: the manual corpus and hypothesis strategies for trees.

:func:`corpus` reads tests/data/cml_manual_corpus.txt (every example line of the
manuals).  The strategies build syntax trees shaped as the parser builds them;
they are shared by tests/test_cml_formatter.py (round trip),
tests/test_cml_parser.py (lark differential oracle) and tests/test_cml_fuzz.py.
"Parser-shaped" means: expressions are left-associative
with ``* /`` under ``+ -`` under one comparison under ``&& ||`` (no grouping
parentheses exist in CML); at most one ``!!(...)`` per statement and only as the
last operand (cml-users-guide.txt 6.8); numbers within the scanner's limits.
"""

from __future__ import annotations

import dataclasses
from functools import cache
from pathlib import Path
from typing import NamedTuple, get_args

from hypothesis import strategies as st

from coolmuscle.cml.ast import (
    REGISTER_KINDS,
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
    ExecOp,
    Expr,
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
    Statement,
    StopBank,
    Str,
    Wait,
)
from coolmuscle.cml.formatter import format_line

CORPUS_PATH = Path(__file__).parent / "data" / "cml_manual_corpus.txt"


class Example(NamedTuple):
    """One corpus row: manual section, expectation ("ok", "cond", "fail"), line."""

    section: str
    expect: str
    line: str

    @property
    def text(self) -> str:
        """The line to parse: condition fragments get actions appended."""
        return self.line + ", ?99, ?98" if self.expect == "cond" else self.line


@cache
def corpus() -> tuple[Example, ...]:
    rows = []
    for raw in CORPUS_PATH.read_text(encoding="utf-8").splitlines():
        if raw and not raw.startswith("#"):
            section, expect, line = raw.split("\t", 2)
            rows.append(Example(section, expect, line))
    return tuple(rows)


def corpus_lines(*expect: str) -> list[str]:
    """Texts of the corpus rows with one of the expectations ``expect``."""
    return [ex.text for ex in corpus() if ex.expect in expect]


motors = st.none() | st.integers(1, 99)
indexes = st.none() | st.integers(0, 9999)
numbers_ = st.integers(0, 9999)
modifiers = st.sampled_from([None, "+", "-"])
values = st.integers(-(10**10 - 1), 10**10 - 1)
texts = st.text(st.characters(min_codepoint=32, max_codepoint=126, exclude_characters='"'),
                max_size=6)

regs = st.builds(Reg, st.sampled_from(REGISTER_KINDS), indexes, motors)
v_regs = st.builds(Reg, st.just("V"), indexes, motors)
inputs = st.builds(Input, numbers_, motors)
leaves = st.one_of(st.builds(Num, values), st.builds(Str, texts), regs, inputs)


@cache
def primary(depth: int) -> st.SearchStrategy[Expr]:
    if depth == 0:
        return leaves
    names = st.sampled_from([f"U{i}" for i in range(1, 7)])
    return leaves | st.builds(Func, names, logic(depth - 1))


@cache
def term(depth: int) -> st.SearchStrategy[Expr]:
    if depth == 0:
        return primary(0)
    return primary(depth) | st.builds(BinOp, st.sampled_from("*/"), term(depth - 1),
                                      primary(depth))


@cache
def arith(depth: int) -> st.SearchStrategy[Expr]:
    if depth == 0:
        return term(0)
    return term(depth) | st.builds(BinOp, st.sampled_from("+-"), arith(depth - 1),
                                   term(depth))


@cache
def compare(depth: int) -> st.SearchStrategy[Expr]:
    ops = st.sampled_from(["==", "!=", ">", ">=", "<", "<="])
    return arith(depth) | st.builds(Compare, ops, arith(depth), arith(depth))


@cache
def logic(depth: int) -> st.SearchStrategy[Expr]:
    if depth == 0:
        return compare(0)
    return compare(depth) | st.builds(Logic, st.sampled_from(["&&", "||"]),
                                      logic(depth - 1), compare(depth))


def attach_not(expr: Expr, inner: Expr) -> Expr:
    """Replace the last operand of ``expr`` by ``!!(inner)`` (6.8: Not comes last)."""
    if isinstance(expr, (BinOp, Compare, Logic)):
        return dataclasses.replace(expr, right=attach_not(expr.right, inner))
    return Not(inner)


expressions = logic(2) | st.builds(attach_not, logic(2), logic(1))
_compound = st.one_of(
    st.builds(Compare, st.sampled_from(["==", "!=", ">", ">=", "<", "<="]), arith(2), arith(2)),
    st.builds(Logic, st.sampled_from(["&&", "||"]), logic(1), compare(2)),
)
conditions = st.one_of(inputs, v_regs, _compound,
                       st.builds(attach_not, _compound | inputs, logic(1)))

simple_statements: st.SearchStrategy[Statement] = st.one_of(
    st.builds(Assign, regs, st.sampled_from(["=", "+=", "-="]), expressions),
    st.builds(Ref, regs, modifiers),
    st.builds(Move, st.sampled_from("YQZ"), indexes, motors, modifiers),
    st.builds(Interp, indexes, motors, modifiers),
    st.builds(Exec, st.sampled_from(get_args(ExecOp)), motors),
    st.builds(Output, st.booleans(), numbers_, motors),
    st.builds(OutputWord, expressions, motors),
    st.builds(Capture, numbers_, motors),
    st.builds(StartBank, st.sampled_from(["B", "L", "LM"]), indexes, motors),
    st.builds(StopBank, st.sampled_from(["L", "LM"]), motors),
    st.builds(Query, indexes, st.none() | st.sampled_from("ASMTVPNRL"), motors),
    st.builds(Call, st.sampled_from(["C", "J", "CL", "JL"]), numbers_, motors),
    st.builds(Loop, st.integers(0, 255), motors),
    st.builds(LoopEnd, motors),
    st.builds(Wait, numbers_, motors),
    st.builds(BankBegin, st.booleans(), numbers_.filter(lambda n: n != 100), motors),
    st.builds(ClearBanks, st.booleans(), motors),
    st.builds(BankEnd, motors),
    st.builds(Alloc, st.sampled_from("PN"), numbers_),
)


def _branch(cond: Expr, then: list[Statement], orelse: list[Statement]) -> Branch:
    if not then:
        orelse = []
        if isinstance(cond, Reg):  # "V1" alone is a Ref, not a branch
            then = [Exec("go")]
    return Branch(cond, tuple(then), tuple(orelse))


branches = st.builds(_branch, conditions, st.lists(simple_statements, max_size=3),
                     st.lists(simple_statements, max_size=3))


@st.composite
def lines(draw: st.DrawFn) -> Line:
    """A Line the parser can produce, with ``source`` = its canonical text."""
    joined = draw(st.booleans())
    statements: tuple[Statement, ...]
    if draw(st.booleans()):
        branch = draw(branches)
        joined = joined or not branch.then
        statements = (branch,)
    else:
        statements = tuple(draw(st.lists(simple_statements, min_size=1, max_size=5)))
        first = statements[0]
        if (len(statements) > 1 and isinstance(first, Ref) and first.modifier is None
                and first.reg.kind == "V"):  # would read back as a branch condition
            statements = (Ref(first.reg, "+"),) + statements[1:]
    text = format_line(Line(statements, joined))
    return Line(statements, joined, text[:-1] if joined else text)
