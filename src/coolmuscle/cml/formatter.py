"""Canonical CML text from the syntax tree (:mod:`coolmuscle.cml.ast`).

This module owns how the motor *prints* CML: the bank listings ``?#.n`` /
``?L#.n`` / ``?1000`` (cml-users-guide.txt 6.6: "S1.1, A1.1, P1.1",
"I1.1&&I2.1, O1.1, O2.1") and ``coolmuscle check``.  The canonical form is:
upper-case letters, statements separated by ``", "``, operators and comparisons
without spaces, branch junctions as ``":"``, motor IDs and indexes printed only
when present in the tree, strings in double quotes, ``";"`` after a joined line.

For every Line the parser can produce, ``parse(format_line(l)) == [l]`` (with
``l.source`` the formatted text without its ``;``).  A tree that the parser
could never produce and whose text would read back as a *different* tree
(``(a+b)*c``: CML has no grouping parentheses; ``B100`` as a BankBegin; a string
holding ``"``) raises :class:`ValueError` instead of printing a lie.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

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

__all__ = ["format_line", "format_statement", "format_expr"]

_EXEC_TEXT: Final = {
    "go": "^", "origin": "|", "go_origin": "|1", "set_origin": "|2", "enable": "(",
    "free": ")", "pause": "]", "pause_motor": "]1", "stop_after_line": "}",
    "estop": "*", "estop_release": "*1", "next_line": ">", "prev_line": "<",
    "save": "$",
}

# Binding strength, loosest first (fidelity.md: && and || share one level).
_LOGIC, _COMPARE, _ADD, _MUL, _PRIMARY = range(5)


def _suffix(index: int | None, motor: int | None) -> str:
    """``#.n`` with each part only when present (index 0 prints, None does not)."""
    text = "" if index is None else str(index)
    return text if motor is None else f"{text}.{motor}"


def _level(expr: Expr) -> int:
    if isinstance(expr, Logic):
        return _LOGIC
    if isinstance(expr, Compare):
        return _COMPARE
    if isinstance(expr, BinOp):
        return _ADD if expr.op in "+-" else _MUL
    return _PRIMARY


def _count_nots(expr: Expr) -> int:
    if isinstance(expr, Not):
        return 1 + _count_nots(expr.operand)
    if isinstance(expr, (BinOp, Compare, Logic)):
        return _count_nots(expr.left) + _count_nots(expr.right)
    if isinstance(expr, Func):
        return _count_nots(expr.arg)
    return 0


def _ends_with_not(expr: Expr) -> bool:
    while isinstance(expr, (BinOp, Compare, Logic)):
        expr = expr.right
    return isinstance(expr, Not)


def _operand(expr: Expr, lowest: int) -> str:
    """``expr`` as an operand that needs at least binding level ``lowest``."""
    if _level(expr) < lowest:
        raise ValueError(f"CML has no grouping parentheses: cannot print {expr!r} here")
    return _expr_text(expr)


def _expr_text(expr: Expr) -> str:
    if isinstance(expr, Num):
        return str(expr.value)
    if isinstance(expr, Reg):
        return expr.kind + _suffix(expr.index, expr.motor)
    if isinstance(expr, Input):
        return "I" + _suffix(expr.index, expr.motor)
    if isinstance(expr, Str):
        if '"' in expr.text or not all(" " <= c <= "~" for c in expr.text):
            raise ValueError(f"a CML string holds printable ASCII without '\"': {expr!r}")
        return f'"{expr.text}"'
    if isinstance(expr, Not):
        return f"!!({_expr_text(expr.operand)})"
    if isinstance(expr, Func):
        return f"{expr.name}({_expr_text(expr.arg)})"
    if isinstance(expr, (BinOp, Compare, Logic)):
        level = _level(expr)
        left_min, right_min = _operand_levels(expr, level)
        return _operand(expr.left, left_min) + expr.op + _operand(expr.right, right_min)
    raise ValueError(f"not a CML expression: {expr!r}")


def _operand_levels(expr: BinOp | Compare | Logic, level: int) -> tuple[int, int]:
    """Left-associative chains; comparisons take arithmetic on both sides (6.9)."""
    if _ends_with_not(expr.left):
        raise ValueError(f"'!!(...)' must end the expression (6.8): {expr!r}")
    if isinstance(expr, Compare):
        return _ADD, _ADD
    return level, level + 1


def format_expr(expr: Expr) -> str:
    """Canonical text of an expression: ``V1.1=V1.1+V2.1``'s right side, ``I1.1&&I2.1``.

    Operators without spaces; ``!(x)`` prints as ``!!(x)`` (cml-users-guide.txt 6.8).
    At most one Not, as the last operand (6.8); otherwise :class:`ValueError`.
    """
    if _count_nots(expr) > 1:
        raise ValueError(f"multiple Not operators in one statement (6.8): {expr!r}")
    if _count_nots(expr) == 1 and not _ends_with_not(expr):
        raise ValueError(f"'!!(...)' must end the expression (6.8): {expr!r}")
    return _expr_text(expr)


# ---------------------------------------------------------------- statements

def _assign(s: Assign) -> str:
    return format_expr(s.target) + s.op + format_expr(s.value)


def _ref(s: Ref) -> str:
    return format_expr(s.reg) + (s.modifier or "")


def _move(s: Move) -> str:
    return s.kind + _suffix(s.index, s.motor) + (s.modifier or "")


def _interp(s: Interp) -> str:
    return "@" + _suffix(s.index, s.motor) + (s.direction or "")


def _exec(s: Exec) -> str:
    if s.op not in _EXEC_TEXT:
        raise ValueError(f"unknown execution command {s.op!r}")
    return _EXEC_TEXT[s.op] + _suffix(None, s.motor)


def _output(s: Output) -> str:
    return ("O" if s.on else "F") + _suffix(s.index, s.motor)


def _output_word(s: OutputWord) -> str:
    return "O" + _suffix(None, s.motor) + "=" + format_expr(s.value)


def _capture(s: Capture) -> str:
    return "#" + _suffix(s.index, s.motor)


def _start_bank(s: StartBank) -> str:
    return "[" + ("" if s.kind == "B" else s.kind) + _suffix(s.index, s.motor)


def _stop_bank(s: StopBank) -> str:
    return "]" + s.kind + _suffix(None, s.motor)


def _query(s: Query) -> str:
    return "?" + (s.letter or "") + _suffix(s.number, s.motor)


def _call(s: Call) -> str:
    return s.kind + _suffix(s.index, s.motor)


def _loop(s: Loop) -> str:
    return "X" + _suffix(s.count, s.motor)


def _loop_end(s: LoopEnd) -> str:
    return "X" + _suffix(None, s.motor) + "-"


def _wait(s: Wait) -> str:
    return "W" + _suffix(s.index, s.motor)


def _bank_begin(s: BankBegin) -> str:
    if s.index == 100:
        raise ValueError("B100 / L100 clear all banks (use ClearBanks)")
    return ("L" if s.ladder else "B") + _suffix(s.index, s.motor)


def _clear_banks(s: ClearBanks) -> str:
    return ("L" if s.ladder else "B") + _suffix(100, s.motor)


def _bank_end(s: BankEnd) -> str:
    return "END" + _suffix(None, s.motor)


def _alloc(s: Alloc) -> str:
    return "\\" + s.kind + str(s.count)


def _is_condition(expr: Expr) -> bool:
    return isinstance(expr, (Compare, Logic, Not, Input)) or (
        isinstance(expr, Reg) and expr.kind == "V")


def _actions(statements: tuple[Statement, ...]) -> str:
    if any(isinstance(s, Branch) for s in statements):
        raise ValueError("a branch cannot hold another branch")
    return ":".join(format_statement(s) for s in statements)


def _branch(s: Branch) -> str:
    """``cond, then, else`` with ``:`` junctions (cml-users-guide.txt 2.2.2 ":")."""
    if not _is_condition(s.condition):
        raise ValueError(f"not a branch condition: {s.condition!r}")
    text = format_expr(s.condition)
    if not s.then:
        if s.orelse or isinstance(s.condition, Reg):
            raise ValueError("a branch without a then part reads back differently")
        return text
    text += ", " + _actions(s.then)
    return text + ", " + _actions(s.orelse) if s.orelse else text


_FORMATTERS: Final[dict[type, Callable[..., str]]] = {
    Assign: _assign, Ref: _ref, Move: _move, Interp: _interp, Exec: _exec,
    Output: _output, OutputWord: _output_word, Capture: _capture,
    StartBank: _start_bank, StopBank: _stop_bank, Query: _query, Call: _call,
    Loop: _loop, LoopEnd: _loop_end, Wait: _wait, BankBegin: _bank_begin,
    ClearBanks: _clear_banks, BankEnd: _bank_end, Alloc: _alloc, Branch: _branch,
}


def format_statement(stmt: Statement) -> str:
    """Canonical text of one statement, e.g. ``P2.1+``, ``?96.1``, ``[L2.1``, ``END``."""
    formatter = _FORMATTERS.get(type(stmt))
    if formatter is None:
        raise ValueError(f"not a CML statement: {stmt!r}")
    return formatter(stmt)


def format_line(line: Line) -> str:
    """Statements joined by ``", "``, plus ``";"`` when joined (6.6 bank readback).

    A Line without statements prints as ``""`` (the parser never returns one).
    """
    statements = line.statements
    if not statements:
        return ""
    if len(statements) > 1:
        if any(isinstance(s, Branch) for s in statements):
            raise ValueError("a branch must be the only statement of its line")
        first = statements[0]
        if isinstance(first, Ref) and first.modifier is None and first.reg.kind == "V":
            raise ValueError("a bare V# first on a line reads back as a branch condition")
    only = statements[0]
    if isinstance(only, Branch) and not only.then and not line.joined:
        raise ValueError("a branch without actions must be joined to the next line")
    text = ", ".join(format_statement(s) for s in statements)
    return text + ";" if line.joined else text
