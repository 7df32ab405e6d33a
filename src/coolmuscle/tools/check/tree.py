"""``coolmuscle check``: walking the CML tree (registers read and written, RT3 steps,
CM2 commands, where a token is on its line).  See :mod:`coolmuscle.tools.check.lint`."""

from __future__ import annotations

from collections.abc import Iterator

from ...cml import ast

__all__ = ["expr_regs", "flat", "steps", "commands", "column", "reg_text", "reads",
           "writes", "numbers", "statement_text", "key", "RegKey"]


def expr_regs(expr: ast.Expr) -> Iterator[ast.Reg | ast.Input]:
    if isinstance(expr, (ast.Reg, ast.Input)):
        yield expr
    elif isinstance(expr, (ast.BinOp, ast.Compare, ast.Logic)):
        yield from expr_regs(expr.left)
        yield from expr_regs(expr.right)
    elif isinstance(expr, ast.Not):
        yield from expr_regs(expr.operand)
    elif isinstance(expr, ast.Func):
        yield from expr_regs(expr.arg)


def flat(statement: ast.Statement) -> Iterator[ast.Statement]:
    """A statement and, for a branch, its actions."""
    yield statement
    if isinstance(statement, ast.Branch):
        yield from statement.then
        yield from statement.orelse


def steps(statement: ast.Statement) -> int:
    """RT3 3.4 steps of one statement (module docstring)."""
    if isinstance(statement, ast.BankEnd):
        return 0
    if isinstance(statement, ast.Branch):
        operands = sum(1 for _ in expr_regs(statement.condition))
        return operands + sum(steps(s) for s in statement.then + statement.orelse)
    if isinstance(statement, ast.Assign):
        return 1 + sum(1 for _ in expr_regs(statement.value))
    if isinstance(statement, ast.OutputWord):
        return 1 + sum(1 for _ in expr_regs(statement.value))
    return 1


def commands(statement: ast.Statement) -> int:
    if isinstance(statement, ast.Branch):
        return 1 + len(statement.then) + len(statement.orelse)
    return 0 if isinstance(statement, ast.BankEnd) else 1


def column(raw: str, needle: str) -> int:
    index = raw.upper().find(needle.upper()) if needle else -1
    return index + 1 if index >= 0 else 1


def numbers(expr: ast.Expr) -> Iterator[int]:
    if isinstance(expr, ast.Num):
        yield expr.value
    elif isinstance(expr, (ast.BinOp, ast.Compare, ast.Logic)):
        yield from numbers(expr.left)
        yield from numbers(expr.right)
    elif isinstance(expr, ast.Func):
        yield from numbers(expr.arg)
    elif isinstance(expr, ast.Not):
        yield from numbers(expr.operand)


def statement_text(statement: ast.Statement) -> str:
    from ...cml.formatter import format_statement
    return format_statement(statement).split(".")[0].rstrip("-")


def reg_text(kind: str, index: int | None, motor: int | None) -> str:
    return f"{kind}{'' if index is None else index}" + ("" if motor is None else f".{motor}")


def reads(statement: ast.Statement) -> Iterator[ast.Reg]:
    """Registers a bank statement reads (values, conditions, selections, moves)."""
    if isinstance(statement, ast.Assign):
        yield from (r for r in expr_regs(statement.value) if isinstance(r, ast.Reg))
    elif isinstance(statement, ast.OutputWord):
        yield from (r for r in expr_regs(statement.value) if isinstance(r, ast.Reg))
    elif isinstance(statement, ast.Branch):
        yield from (r for r in expr_regs(statement.condition) if isinstance(r, ast.Reg))
    elif isinstance(statement, ast.Ref) and statement.reg.kind != "K":
        yield statement.reg
    elif isinstance(statement, ast.Move):
        yield ast.Reg("P", statement.index, statement.motor)
    elif isinstance(statement, ast.Interp) and statement.index is not None:
        yield ast.Reg("P", statement.index, statement.motor)
    elif isinstance(statement, ast.Wait) and statement.index:
        yield ast.Reg("T", statement.index, statement.motor)


def writes(statement: ast.Statement) -> Iterator[ast.Reg]:
    if isinstance(statement, ast.Assign):
        yield statement.target
    elif isinstance(statement, ast.Capture):
        yield ast.Reg("P", statement.index, statement.motor)


RegKey = tuple[str, int, int]


def key(reg: ast.Reg, default_motor: int) -> RegKey:
    return reg.kind, reg.number, reg.motor or default_motor


