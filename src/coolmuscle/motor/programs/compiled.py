"""Ladder statements compiled to Python closures, so that a scan costs microseconds.

A ladder bank is scanned every few milliseconds for as long as the motor runs
(cml-users-guide.txt 2.2.3, K63), so its statements are turned once (per version of
the banks) into closures instead of being interpreted from the tree at every scan.
The closures mean exactly what :mod:`.evaluate` and :mod:`.direct` mean:
signed 32-bit arithmetic, truncating division, 0 for a division by zero, V strings
packed, V states read live (tests/test_ladder_compiled.py compares them on random
trees).  Anything unusual (``W#``, a ``T#`` or ``CL``/``JL`` that is not the last
action of a branch, bank commands, string assignments, other motors' registers) is
left to the interpreter in :mod:`.ladder`: :func:`compile_statement` returns ``None``.

A compiled statement adds its RT3 3.4 steps to the scanner's clock and returns
``None``, or, as its last act, a :class:`~.bankexec.Sleep` (``T#``) or the
:class:`~coolmuscle.cml.ast.Call` (``CL``/``JL``) for the scanner to carry out.
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from ...cml import ast
from ...errors import MotorError, OutOfRangeError
from ..state.memory import LIMIT_1E9, WRITABLE_STATES, VNumber, VState
from .bankcheck import expr_steps, statement_steps
from .bankexec import STEP_NS, Sleep, run_plain
from .direct import MotorEval
from .evaluate import call_function, pack_string, wrap32
from .queries import display_reply

if TYPE_CHECKING:
    from ..context import Context
    from ..core import MotorCore

Reader = Callable[[], int]
Compiled = Callable[[], object]
_PLAIN_KINDS = frozenset("PSAMTNRH")
_COMPARE: dict[str, Callable[[int, int], bool]] = {
    "==": operator.eq, "!=": operator.ne, ">": operator.gt, ">=": operator.ge,
    "<": operator.lt, "<=": operator.le}


class Clock(Protocol):
    """What a compiled statement advances: the scan's step clock (ns)."""

    clock: int


# ---------------------------------------------------------------- expressions

def _divide(a: int, b: int) -> int:
    if b == 0:
        return 0
    q = abs(a) // abs(b)
    return wrap32(q if (a >= 0) == (b >= 0) else -q)


def _register(reg: ast.Reg, motor: MotorCore) -> Reader:
    if reg.motor not in (None, motor.id):
        host = MotorEval(motor)
        return lambda: host.register_value(reg)
    kind, index = reg.kind, reg.number
    if kind == "K":
        def read_k() -> int:
            try:
                return motor.params.get(index)
            except LookupError:
                return 0   # as MotorEval.register_value: a register that does not exist
        return read_k
    if kind == "V":
        def read_v() -> int:
            try:
                cell = motor.memory.data["V"][index]
            except IndexError:
                return 0
            cls = cell.__class__
            if cls is VNumber:
                number: int = cell.value
                return number
            if cls is VState:
                return motor.state_value(cell.name)
            return motor.v_numeric(cell)        # a string
        return read_v

    def read() -> int:
        try:
            value: int = motor.memory.data[kind][index]
        except IndexError:
            return 0
        return value
    return read


def compile_expr(expr: ast.Expr, motor: MotorCore) -> Reader:
    """A closure computing ``evaluate(expr)`` on ``motor`` (6.7-6.9)."""
    if isinstance(expr, ast.Num):
        value = wrap32(expr.value)
        return lambda: value
    if isinstance(expr, ast.Str):
        packed = pack_string(expr.text)
        return lambda: packed
    if isinstance(expr, ast.Reg):
        return _register(expr, motor)
    if isinstance(expr, ast.Input):
        host, number, which = MotorEval(motor), expr.index, expr.motor
        return lambda: int(host.input_signal(number, which))
    if isinstance(expr, ast.BinOp):
        return _arithmetic(expr, motor)
    if isinstance(expr, ast.Compare):
        test = _COMPARE[expr.op]
        return _binary(lambda a, b: int(test(a, b)), expr, motor)
    if isinstance(expr, ast.Logic):
        left, right = compile_expr(expr.left, motor), compile_expr(expr.right, motor)
        if expr.op == "&&":
            return lambda: int((left() != 0) & (right() != 0))
        return lambda: int((left() != 0) | (right() != 0))
    if isinstance(expr, ast.Not):
        inner = compile_expr(expr.operand, motor)
        return lambda: int(inner() == 0)
    if isinstance(expr, ast.Func):
        arg, name, host2 = compile_expr(expr.arg, motor), expr.name, MotorEval(motor)
        return lambda: call_function(name, arg(), host2)
    raise TypeError(f"not an expression: {expr!r}")


def _arithmetic(expr: ast.BinOp, motor: MotorCore) -> Reader:
    """``+ - *`` inline (wrapped to 32 bits only when they leave it), ``/`` as 6.7."""
    left, right = compile_expr(expr.left, motor), compile_expr(expr.right, motor)
    if expr.op == "/":
        return lambda: _divide(left(), right())
    if expr.op == "+":
        def add() -> int:
            v = left() + right()
            return v if -0x8000_0000 <= v <= 0x7FFF_FFFF else wrap32(v)
        return add
    if expr.op == "-":
        def sub() -> int:
            v = left() - right()
            return v if -0x8000_0000 <= v <= 0x7FFF_FFFF else wrap32(v)
        return sub
    return lambda: wrap32(left() * right())


def _binary(op: Callable[[int, int], int], expr: ast.BinOp | ast.Compare,
            motor: MotorCore) -> Reader:
    left, right = compile_expr(expr.left, motor), compile_expr(expr.right, motor)
    return lambda: op(left(), right())


def compile_condition(expr: ast.Expr, motor: MotorCore) -> Callable[[], bool]:
    """Truth of a branch condition: a value alone means "> 0" (6.3 "V")."""
    reader = compile_expr(expr, motor)
    if isinstance(expr, (ast.Reg, ast.Num, ast.BinOp, ast.Func)):
        return lambda: reader() > 0
    return lambda: reader() != 0


# ---------------------------------------------------------------- statements

def _assign(stmt: ast.Assign, motor: MotorCore, ctx: Context, quiet: bool, clock: Clock,
            display: Callable[[MotorCore, ast.Reg, int], str]) -> Compiled | None:
    """An assignment as one closure: steps, value, store, display, errors."""
    reg = stmt.target
    if reg.motor not in (None, motor.id) or reg.kind not in _PLAIN_KINDS | {"V", "K"}:
        return None
    if isinstance(stmt.value, ast.Str):
        return None
    value = compile_expr(stmt.value, motor)
    if stmt.op != "=":   # as direct.assign_value: register +/- value, then range-checked
        base, delta = _register(reg, motor), value
        sign = 1 if stmt.op == "+=" else -1
        value = lambda: base() + sign * delta()  # noqa: E731
    kind, index = reg.kind, reg.number
    steps = statement_steps(stmt) * STEP_NS

    def run() -> None:
        clock.clock += steps
        try:
            result = value()
            if kind == "V":
                memory = motor.memory
                cells = memory.data["V"]
                cell = cells[index]
                if cell.__class__ is VState and cell.name in WRITABLE_STATES:
                    motor.write_state(cell.name, result)
                elif type(result) is int and -LIMIT_1E9 <= result <= LIMIT_1E9:
                    cells[index] = VNumber(result)       # memory.set_v_number, inline
                else:
                    memory.set_v_number(index, result)   # raises its error
            else:
                motor.write_register(kind, index, result)
            if not quiet:
                motor.say(ctx, display(motor, reg, result))
        except MotorError as error:
            motor.report_error(ctx, error)
        except (LookupError, ValueError, ArithmeticError, TypeError):
            motor.report_error(ctx, OutOfRangeError())
    return run


def compile_statement(stmt: ast.Statement, motor: MotorCore, ctx: Context, quiet: bool,
                      clock: Clock, display: Callable[[MotorCore, ast.Reg, int], str],
                      last: bool = True) -> Compiled | None:
    """A closure for a ladder statement, or ``None`` to leave it to the interpreter."""
    if isinstance(stmt, ast.Branch):
        return _branch(stmt, motor, ctx, quiet, clock, display)
    if isinstance(stmt, ast.Assign):
        return _assign(stmt, motor, ctx, quiet, clock, display)
    steps = statement_steps(stmt) * STEP_NS
    body = _body(stmt, motor, ctx, quiet, display, last)
    if body is None:
        return None

    def run() -> object:
        clock.clock += steps
        try:
            return body()
        except MotorError as error:
            motor.report_error(ctx, error)
        except (LookupError, ValueError, ArithmeticError, TypeError):
            motor.report_error(ctx, OutOfRangeError())
        return None
    return run


def _body(stmt: ast.Statement, motor: MotorCore, ctx: Context, quiet: bool,
          display: Callable[[MotorCore, ast.Reg, int], str], last: bool) -> Compiled | None:
    if isinstance(stmt, ast.Ref):
        return _ref(stmt, motor, ctx, last)
    if isinstance(stmt, ast.Call):
        return (lambda: stmt) if last else None     # CL JL (RT3: C J too, ladder._call)
    if isinstance(stmt, (ast.Wait, ast.StartBank, ast.StopBank, ast.ClearBanks,
                         ast.BankBegin, ast.BankEnd)):
        return None
    return lambda: run_plain(motor, stmt, ctx)


def _ref(stmt: ast.Ref, motor: MotorCore, ctx: Context, last: bool) -> Compiled | None:
    reg = stmt.reg
    if reg.motor not in (None, motor.id):
        return None
    if reg.kind == "T":
        if not last:
            return None
        read = _register(reg, motor)

        def wait() -> object:
            ns = max(read(), 0) * 1_000_000
            return Sleep(ns) if ns else None
        return wait
    return lambda: motor.say(ctx, display_reply(motor, reg))


def _actions(stmts: tuple[ast.Statement, ...], motor: MotorCore, ctx: Context, quiet: bool,
             clock: Clock, display: Callable[[MotorCore, ast.Reg, int], str]
             ) -> Callable[[], object] | None:
    fns = [compile_statement(s, motor, ctx, quiet, clock, display, i == len(stmts) - 1)
           for i, s in enumerate(stmts)]
    if any(fn is None for fn in fns):
        return None
    if len(fns) == 1:
        return fns[0]

    def run() -> object:
        result = None
        for fn in fns:
            result = fn()  # type: ignore[misc]
        return result
    return run


def _branch(stmt: ast.Branch, motor: MotorCore, ctx: Context, quiet: bool, clock: Clock,
            display: Callable[[MotorCore, ast.Reg, int], str]) -> Compiled | None:
    if any(isinstance(s, ast.Wait) for s in stmt.then):
        return None
    then = _actions(stmt.then, motor, ctx, quiet, clock, display)
    orelse = _actions(stmt.orelse, motor, ctx, quiet, clock, display)
    if then is None or orelse is None:
        return None
    test = compile_condition(stmt.condition, motor)
    steps = expr_steps(stmt.condition) * STEP_NS

    def safe_test() -> bool:
        try:
            return test()
        except (MotorError, LookupError, ValueError, ArithmeticError, TypeError):
            return False

    def run() -> object:
        clock.clock += steps
        return then() if safe_test() else orelse()
    return run
