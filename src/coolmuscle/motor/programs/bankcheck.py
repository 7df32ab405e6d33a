"""What may be stored in a bank, what a bank line costs, and the motor IDs it names.

This module owns the *static* rules of bank lines (cml-users-guide.txt 2.2.2, 2.2.3,
6.3-6.6; cm-banks-rt3.txt 1.1, 1.2, 3.3, 3.4):

* :func:`fill_motor` writes the bank's motor ID into every command and register that
  names none, as the motor does before it stores a line (``S1`` in ``B1.2`` is ``S1.2``);
* :func:`check_line` refuses what cannot be stored: a command 6.5 marks as unusable in
  that kind of bank (error03), a command that cannot follow another on one line
  (error04), more than 40 characters between commas and, on RT3, literal numbers
  (error01);
* :func:`statement_steps` / :func:`line_steps` count RT3 steps (3.4: "1 step is any
  command other than operands, math symbols and carriage returns", the bank start
  included), which also time the ladder (250 µs a step); :func:`line_commands`
  counts CM2 commands (2.2.2 "500 commands in total").

The choices made where the manuals are silent are in docs/fidelity.md "Banks and ladder".
"""

from __future__ import annotations

import dataclasses
from typing import Final

from ...cml import ast
from ...errors import CannotFollowError, CmlSyntaxError, NotAllowedInBankError
from ..state.firmware import Firmware

#: RT3 3.3.2: "The maximum amount of characters between a , (comma) and a carriage return is 40."
MAX_CHARS_BETWEEN_COMMAS: Final = 40

_EXEC_SYMBOL: Final = {
    "go": "^", "origin": "|", "go_origin": "|1", "set_origin": "|2", "enable": "(",
    "free": ")", "pause": "]", "pause_motor": "]1", "stop_after_line": "}",
    "estop": "*", "estop_release": "*1", "next_line": ">", "prev_line": "<", "save": "$",
}
#: 6.5 column P / L "×" and 2.2.2 / 2.2.3 "]1, [L, ]L, >, <, }, $ commands can not be used".
_NEVER_IN_BANK: Final = frozenset({"pause_motor", "stop_after_line", "next_line",
                                   "prev_line", "save"})
#: Statements after which nothing may follow on the same line (they end the line's flow).
_LINE_ENDERS: Final = (ast.Call, ast.Loop, ast.LoopEnd, ast.Wait)
_MOTIONS: Final = (ast.Move, ast.Interp)


def symbol(stmt: ast.Statement | ast.Expr) -> str:
    """The command as the XX/DD of error03/error04: ``^``, ``X``, ``[L``, ``?1000``, ``P``."""
    if isinstance(stmt, ast.Assign):
        return stmt.target.kind
    if isinstance(stmt, ast.Ref):
        return stmt.reg.kind
    if isinstance(stmt, ast.Reg):
        return stmt.kind
    if isinstance(stmt, ast.Input):
        return "I"
    if isinstance(stmt, (ast.Compare, ast.Logic, ast.BinOp)):
        return symbol(stmt.left)
    if isinstance(stmt, ast.Not):
        return "!!"
    if isinstance(stmt, ast.Branch):
        return symbol(stmt.condition)
    return _command_symbol(stmt)


def _command_symbol(stmt: object) -> str:
    simple = {ast.Interp: "@", ast.Capture: "#", ast.OutputWord: "O", ast.Loop: "X",
              ast.LoopEnd: "X-", ast.Wait: "W", ast.BankEnd: "END", ast.Alloc: "\\",
              ast.Func: "U", ast.Num: "", ast.Str: ""}
    if type(stmt) in simple:
        return simple[type(stmt)]
    if isinstance(stmt, ast.Move):
        return stmt.kind
    if isinstance(stmt, ast.Exec):
        return _EXEC_SYMBOL.get(stmt.op, "?")
    if isinstance(stmt, ast.Output):
        return "O" if stmt.on else "F"
    if isinstance(stmt, ast.StartBank):
        return "[" + ("" if stmt.kind == "B" else stmt.kind)
    if isinstance(stmt, ast.StopBank):
        return "]" + stmt.kind
    if isinstance(stmt, ast.Query):
        return _query_symbol(stmt)
    if isinstance(stmt, ast.Call):
        return stmt.kind
    if isinstance(stmt, (ast.BankBegin, ast.ClearBanks)):
        letter = "L" if stmt.ladder else "B"
        return letter + ("100" if isinstance(stmt, ast.ClearBanks) else "")
    return "?"


def _query_symbol(q: ast.Query) -> str:
    text = "?" + (q.letter or "")
    return text + ("" if q.number is None or q.letter else str(q.number))


# ---------------------------------------------------------------- motor IDs

def fill_motor(line: ast.Line, motor_id: int) -> ast.Line:
    """``line`` with every omitted motor ID set to ``motor_id`` (the bank's motor)."""
    statements = tuple(_fill_stmt(s, motor_id) for s in line.statements)
    return dataclasses.replace(line, statements=statements)


def _fill_expr(expr: ast.Expr, m: int) -> ast.Expr:
    if isinstance(expr, (ast.Reg, ast.Input)):
        return expr if expr.motor is not None else dataclasses.replace(expr, motor=m)
    if isinstance(expr, (ast.BinOp, ast.Compare, ast.Logic)):
        return dataclasses.replace(expr, left=_fill_expr(expr.left, m),
                                   right=_fill_expr(expr.right, m))
    if isinstance(expr, ast.Func):
        return dataclasses.replace(expr, arg=_fill_expr(expr.arg, m))
    if isinstance(expr, ast.Not):
        return dataclasses.replace(expr, operand=_fill_expr(expr.operand, m))
    return expr


def _fill_stmt(stmt: ast.Statement, m: int) -> ast.Statement:
    if isinstance(stmt, ast.Assign):
        target = _fill_expr(stmt.target, m)
        return dataclasses.replace(stmt, target=target,  # type: ignore[arg-type]
                                   value=_fill_expr(stmt.value, m))
    if isinstance(stmt, ast.Ref):
        return dataclasses.replace(stmt, reg=_fill_expr(stmt.reg, m))  # type: ignore[arg-type]
    if isinstance(stmt, ast.Branch):
        return ast.Branch(_fill_expr(stmt.condition, m),
                          tuple(_fill_stmt(s, m) for s in stmt.then),
                          tuple(_fill_stmt(s, m) for s in stmt.orelse))
    if isinstance(stmt, ast.OutputWord):
        stmt = dataclasses.replace(stmt, value=_fill_expr(stmt.value, m))
    if isinstance(stmt, ast.Alloc) or getattr(stmt, "motor", 0) is not None:
        return stmt
    return dataclasses.replace(stmt, motor=m)


# ---------------------------------------------------------------- steps

def expr_steps(expr: ast.Expr) -> int:
    """Operands count one step each; operators and U# wrappers count nothing (RT3 3.4)."""
    if isinstance(expr, (ast.BinOp, ast.Compare, ast.Logic)):
        return expr_steps(expr.left) + expr_steps(expr.right)
    if isinstance(expr, ast.Func):
        return expr_steps(expr.arg)
    if isinstance(expr, ast.Not):
        return expr_steps(expr.operand)
    return 1


def statement_steps(stmt: ast.Statement) -> int:
    """RT3 3.4 steps of one statement, every branch part counted (storage)."""
    if isinstance(stmt, ast.Branch):
        return (expr_steps(stmt.condition) + sum(map(statement_steps, stmt.then))
                + sum(map(statement_steps, stmt.orelse)))
    if isinstance(stmt, ast.Assign):
        return 1 + expr_steps(stmt.value)
    if isinstance(stmt, ast.OutputWord):
        return 1 + expr_steps(stmt.value)
    if isinstance(stmt, ast.BankEnd):
        return 0
    return 1


def line_steps(line: ast.Line) -> int:
    """RT3 steps of one stored line."""
    return sum(map(statement_steps, line.statements))


def line_commands(line: ast.Line) -> int:
    """CM2 commands of one stored line: each comma or colon element (2.2.2)."""
    total = 0
    for stmt in line.statements:
        if isinstance(stmt, ast.Branch):
            total += 1 + len(stmt.then) + len(stmt.orelse)
        elif not isinstance(stmt, ast.BankEnd):
            total += 1
    return total


def line_cost(line: ast.Line, firmware: Firmware) -> int:
    """What a line uses of the bank memory: RT3 steps, or CM2 commands."""
    return line_steps(line) if firmware.max_bank_steps is not None else line_commands(line)


def bank_header_cost(firmware: Firmware) -> int:
    """RT3 counts the start of a bank as a step (3.4 "These include the start of the bank")."""
    return 1 if firmware.max_bank_steps is not None else 0


def memory_limit(firmware: Firmware) -> int:
    """RT3: 200 steps shared by all banks; CM2: 500 commands per motor (2.2.2)."""
    if firmware.max_bank_steps is not None:
        return firmware.max_bank_steps
    return firmware.max_bank_commands or 500


# ---------------------------------------------------------------- checks

def check_line(line: ast.Line, *, ladder: bool, firmware: Firmware) -> None:
    """Raise the motor's error for a line that cannot be stored in this kind of bank."""
    _check_length(line)
    rt3 = firmware.max_bank_steps is not None
    for stmt in line.statements:
        _check_allowed(stmt, ladder=ladder, rt3=rt3)
        if rt3:
            _check_no_literal(stmt, line)
    _check_sequence(line.statements, head=None)
    for stmt in line.statements:
        if isinstance(stmt, ast.Branch):
            _check_branch(stmt)
        elif isinstance(stmt, ast.Wait):
            raise CmlSyntaxError("W waits in the then part of a branch only",
                                 text=line.source, position=0)
    _check_motions(line.statements)


def _check_length(line: ast.Line) -> None:
    piece, quoted, start = 0, False, 0
    text = line.source
    for i, ch in enumerate(text + ","):
        if ch == '"':
            quoted = not quoted
        elif ch == "," and not quoted:
            piece = len(text[start:i].strip(" \t"))
            if piece > MAX_CHARS_BETWEEN_COMMAS:
                raise CmlSyntaxError(f"more than {MAX_CHARS_BETWEEN_COMMAS} characters "
                                     "between commas", text=text, position=start)
            start = i + 1


def _allowed_exec(op: str, *, rt3: bool) -> bool:
    if op in _NEVER_IN_BANK:
        return False
    return op != "go" or rt3  # 6.5 "^" P ×, L ×; RT3 7.1-7.3 run "^.1" in logic banks


def _check_allowed(stmt: ast.Statement, *, ladder: bool, rt3: bool) -> None:
    """error03 (6.3-6.6): commands that cannot be defined in this kind of bank."""
    bad = False
    if isinstance(stmt, (ast.BankBegin, ast.ClearBanks, ast.BankEnd, ast.Alloc)):
        bad = True
    elif isinstance(stmt, ast.Exec):
        bad = not _allowed_exec(stmt.op, rt3=rt3)
    elif isinstance(stmt, (ast.StopBank,)) or (
            isinstance(stmt, ast.StartBank) and stmt.kind != "B"):
        bad = not ladder                       # 6.5 "[L", "]L": P ×, L ○
    elif isinstance(stmt, ast.Call):
        # C/J program only, CL/JL ladder only; RT3 1.1 calls with C# in its logic-bank
        # examples ("L1.1 I1.1, C2.1, C3.1 END.1"): there they are CL#/JL#
        bad = ladder != stmt.kind.endswith("L") and not (ladder and rt3)
    elif isinstance(stmt, (ast.Loop, ast.LoopEnd)):
        bad = ladder                           # 4.5.1 "X command can not be available"
    elif isinstance(stmt, ast.Move):
        bad = ladder                           # 6.3 only: Y Q Z move the motor
    elif isinstance(stmt, ast.Query):
        bad = stmt.letter is not None or stmt.number in (999, 1000)  # 6.6 second table
    if bad:
        raise NotAllowedInBankError(xx=symbol(stmt))
    if isinstance(stmt, ast.Branch):
        for inner in stmt.then + stmt.orelse:
            _check_allowed(inner, ladder=ladder, rt3=rt3)


def _literals(expr: ast.Expr) -> bool:
    if isinstance(expr, ast.Num):
        return True
    if isinstance(expr, (ast.BinOp, ast.Compare, ast.Logic)):
        return _literals(expr.left) or _literals(expr.right)
    if isinstance(expr, ast.Func):
        return _literals(expr.arg)
    if isinstance(expr, ast.Not):
        return _literals(expr.operand)
    return False


def _check_no_literal(stmt: ast.Statement, line: ast.Line) -> None:
    """RT3 1.2: a register "cannot be set in the bank with an actual number"."""
    exprs: list[ast.Expr] = []
    if isinstance(stmt, (ast.Assign, ast.OutputWord)):
        exprs.append(stmt.value)
    elif isinstance(stmt, ast.Branch):
        exprs.append(stmt.condition)
        for inner in stmt.then + stmt.orelse:
            _check_no_literal(inner, line)
    if any(_literals(e) for e in exprs):
        raise CmlSyntaxError("RT3 banks take no literal numbers (set a register first)",
                             text=line.source, position=0)


def _check_sequence(statements: tuple[ast.Statement, ...], head: str | None) -> None:
    """error04: C J CL JL X X- W end their action list; X and X- start a line."""
    for i, stmt in enumerate(statements):
        if isinstance(stmt, (ast.Loop, ast.LoopEnd)) and (i > 0 or head is not None):
            before = head if i == 0 else symbol(statements[i - 1])
            raise CannotFollowError(xx=before or "?", dd=symbol(stmt))
        if isinstance(stmt, _LINE_ENDERS) and i + 1 < len(statements):
            raise CannotFollowError(xx=symbol(stmt), dd=symbol(statements[i + 1]))


def _check_branch(branch: ast.Branch) -> None:
    head = symbol(branch.condition)
    _check_sequence(branch.then, head)
    _check_sequence(branch.orelse, head)
    for inner in branch.orelse:
        if isinstance(inner, ast.Wait):
            raise CannotFollowError(xx=head, dd="W")  # W waits in the then part only


def _motion_target(stmt: ast.Statement) -> tuple[str, int | None] | None:
    if isinstance(stmt, ast.Ref) and stmt.reg.kind == "P":
        return "P", stmt.reg.motor
    if isinstance(stmt, _MOTIONS):
        return symbol(stmt), stmt.motor
    return None


def _check_motions(statements: tuple[ast.Statement, ...]) -> None:
    """error04: after Y, Q or Z no other motion of that motor on the same line (4.3.2)."""
    finished: dict[int | None, str] = {}
    for stmt in statements:
        motion = _motion_target(stmt)
        if motion is None:
            continue
        sym, motor = motion
        if motor in finished:
            raise CannotFollowError(xx=finished[motor], dd=sym)
        if sym in ("Y", "Q", "Z"):
            finished[motor] = sym
