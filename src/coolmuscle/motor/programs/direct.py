"""Direct mode: executing a statement the moment it arrives (cml-users-guide.txt 2.1, 6.5 "D").

A register named alone is a query (6.6); an assignment stores data (2.1.1) or sets a
K parameter (ch. 3); execution commands act at once (2.1.2).  Out-of-range values are
not applied and give ``error00.n: Out Of Range!!`` when K23 includes 16.
Bank commands are delegated to the chain's bank hooks (program and ladder banks).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from ...cml import ast
from ...cml.ast import inner_motor
from ...errors import MotorError, OutOfRangeError, StoreError
from ..state.memory import WRITABLE_STATES, VState
from ..status import Report
from .coordinated import direct_interp
from .evaluate import EvalHost, condition, evaluate
from .queries import query_lines, register_reply

if TYPE_CHECKING:
    from ..context import Context
    from ..core import MotorCore

log = logging.getLogger(__name__)


class MotorEval(EvalHost):
    """Evaluation of expressions for one motor (reads other motors through its chain)."""

    def __init__(self, motor: MotorCore) -> None:
        self.motor = motor

    def _target(self, motor_id: int | None) -> MotorCore | None:
        if motor_id is None or motor_id == self.motor.id:
            return self.motor
        return self.motor.bus.motor(motor_id)

    def register_value(self, reg: ast.Reg) -> int:
        target = self._target(reg.motor)
        if target is None:
            return 0
        try:
            return target.register_number(reg)
        except (IndexError, LookupError, ValueError):
            return 0

    def input_signal(self, number: int, motor: int | None) -> bool:
        target = self._target(motor)
        return bool(target and target.io.input_signal(number))

    def table(self, kind: str, index: int) -> int:
        value = self.motor.memory.get(kind, index)
        return value if isinstance(value, int) else self.motor.v_numeric(value)

    def sine(self, x: int) -> int:
        return self.motor.firmware.sine(x)

    def cosine(self, x: int) -> int:
        return self.motor.firmware.cosine(x)


def assign_value(motor: MotorCore, stmt: ast.Assign, ctx: Context) -> int | str | None:
    """Compute and store an assignment; returns the stored value (for ladder display)."""
    reg = stmt.target
    host = MotorEval(motor)
    if reg.kind == "V" and isinstance(stmt.value, ast.Str) and stmt.op == "=":
        motor.write_register("V", reg.number, stmt.value.text)
        return None
    value = evaluate(stmt.value, host)
    if reg.kind == "K" and reg.number == 20 and stmt.op == "=" and \
            motor.reports(Report.MESSAGES):
        motor.propose_baud(ctx, value)    # ch. 3 K23 16: "Change Baud Rate ?? XXX kbps (Y/N)"
        return value
    if stmt.op != "=":
        if reg.kind == "P" and not motor.resolution.incremental_allowed:
            # ch. 3 K37: "40-70, the incremental motion cannot be executed"
            raise OutOfRangeError()
        if reg.kind == "P" and reg.number == 0 and not ctx.program and not ctx.ladder:
            base = motor.position()          # 6.2: direct P0 is relative to the current position
        else:
            base = motor.register_number(reg)
        value = base + value if stmt.op == "+=" else base - value
    if reg.kind == "V":
        current = motor.memory.get("V", reg.number)
        if isinstance(current, VState) and current.name in WRITABLE_STATES:
            motor.write_state(current.name, value)
            return value
    motor.write_register(reg.kind, reg.number, value)
    return value


def run_statement(motor: MotorCore, stmt: ast.Statement, ctx: Context) -> None:
    """Execute one statement in direct mode on ``motor``."""
    try:
        _dispatch(motor, stmt, ctx)
    except MotorError as error:
        motor.report_error(ctx, error)
    except (IndexError, LookupError):
        motor.report_error(ctx, OutOfRangeError())


def _dispatch(motor: MotorCore, stmt: ast.Statement, ctx: Context) -> None:
    if isinstance(stmt, ast.Assign):
        assign_value(motor, stmt, ctx)
    elif isinstance(stmt, ast.Ref):
        motor.say(ctx, register_reply(motor, stmt.reg))
    elif isinstance(stmt, ast.Query):
        _query(motor, stmt, ctx)
    elif isinstance(stmt, ast.Exec):
        _exec(motor, stmt, ctx)
    elif isinstance(stmt, ast.Output):
        motor.set_output(stmt.index, stmt.on)
    elif isinstance(stmt, ast.OutputWord):
        motor.set_output_word(evaluate(stmt.value, MotorEval(motor)))
    elif isinstance(stmt, ast.Capture):
        motor.capture(stmt.index)
    elif isinstance(stmt, ast.Move):
        motor.direct_move(stmt)
    elif isinstance(stmt, ast.Interp):
        direct_interp(motor, stmt, ctx)          # 2.1.2 "@", 4.4 (.coordinated)
    elif isinstance(stmt, ast.Alloc):
        motor.memory.allocate(stmt.kind, stmt.count)
    elif isinstance(stmt, ast.Branch):
        branch = stmt.then if condition(stmt.condition, MotorEval(motor)) else stmt.orelse
        for inner in branch:
            route(motor, inner, ctx)
    else:
        motor.bus.bank_command(motor, stmt, ctx)


def route(motor: MotorCore, stmt: ast.Statement, ctx: Context) -> None:
    """Run ``stmt`` on the motor it names (``motor`` when it names none); a statement
    for an ID not on the chain goes to the chain (the COM1 device, or nobody)."""
    motor_id = inner_motor(stmt) or motor.id
    target = motor.bus.motor(motor_id)
    if target is not None:
        run_statement(target, stmt, ctx)
    else:
        motor.bus.beyond_chain(motor_id, stmt, ctx)


def _query(motor: MotorCore, q: ast.Query, ctx: Context) -> None:
    lines = query_lines(motor, q)
    if lines is None:
        lines = motor.bus.bank_query(motor, q)
    for line in lines or ():
        motor.say(ctx, line)


def _exec(motor: MotorCore, stmt: ast.Exec, ctx: Context) -> None:
    op = stmt.op
    if op == "go":
        motor.go()
    elif op == "origin":
        motor.origin_search()
    elif op == "go_origin":
        motor.go_origin()
    elif op == "set_origin":
        motor.set_origin()
    elif op == "enable":
        motor.enable()
    elif op == "free":
        motor.free()
    elif op == "save":
        try:
            motor.bus.save(motor.id)
        except StoreError as exc:   # full disk, read-only file: the host is told, always
            log.warning("motor %d: $ not saved: %s", motor.id, exc)
            motor.say(ctx, f"not saved.{motor.id}: {exc}", kind="message")
            return
        motor.say(ctx, f"saved.{motor.id}")
    else:
        motor.bus.chain_command(motor, stmt, ctx)
