"""Compiled ladder statements mean what the interpreter means (property tests).

The ladder scanner runs closures from :mod:`coolmuscle.motor.programs.compiled`; program
banks and direct mode use :mod:`coolmuscle.motor.programs.evaluate` /
:mod:`coolmuscle.motor.programs.direct`.  Random trees (tests/cml_support.py strategies) on
a two-motor chain with data in its registers must give the same value, the same stored data
and the same printed lines both ways.
"""

from __future__ import annotations

import dataclasses

from hypothesis import given, settings
from hypothesis import strategies as st

from cml_support import expressions
from coolmuscle.chain.daisy import Chain
from coolmuscle.cml import ast
from coolmuscle.motor.programs.compiled import compile_expr, compile_statement
from coolmuscle.motor.programs.direct import MotorEval
from coolmuscle.motor.programs.evaluate import evaluate
from coolmuscle.motor.programs.ladder import _assigned

SETUP = ("K23.1=17", "V1.1=7", "V2.1=-3", 'V3.1="ab"', 'V4.1="Px"', 'V5.1="ST"', "P1.1=1000",
         "S2.1=-40", "V6.1=-2000000000", "V7.1=1000000000",
         "N0.1=3", "N1.1=2", "N2.1=5", "N3.1=1", "R1.1=9", "V1.2=11", "P.1=20", "^.1")


def chain() -> Chain:
    c = Chain(motors=2)
    for line in SETUP:
        c.execute(line)
    c.kernel.run(until=50_000_000)   # the motor is moving: Px changes
    return c


def _small(node: object) -> object:
    """Keep motor IDs on the chain or absent and memory numbers small (some missing)."""
    if isinstance(node, (ast.Reg, ast.Input)):
        motor = None if node.motor is None else node.motor % 3 or None
        index = node.index if not isinstance(node, ast.Reg) else (
            None if node.index is None else node.index % 20)
        if isinstance(node, ast.Input):
            return ast.Input(node.index % 8, motor)
        kind = node.kind if node.kind != "K" else "K"
        if kind == "K" and index is not None:
            index += 15   # K15..K34: some exist
        return ast.Reg(kind, index, motor)
    if isinstance(node, ast.Num):
        return node
    if dataclasses.is_dataclass(node) and not isinstance(node, type):
        changes = {f.name: _small(getattr(node, f.name)) for f in dataclasses.fields(node)
                   if not isinstance(getattr(node, f.name), (str, int, type(None)))}
        return dataclasses.replace(node, **changes)  # type: ignore[arg-type]
    return node


class _Clock:
    clock = 0


TABLE = ["V1.1/V2.1", "V2.1/V1.1", "V1.1/V8.1", "V6.1/V2.1", "V2.1*V6.1", "V7.1+V7.1+V7.1",
         "V6.1-V7.1", "V1.1-V2.1*P1.1", "V3.1", "V3.1+1", "V4.1*2", "V5.1", "V99.1", "P1.2",
         "V1.2", "V1.3", "K23.1", "K99.1", "I1.1", "I9.1", "U1(V1.1*1000)", "U2(V2.1)",
         "U3(P1.1)", "U3(V2.1)", "U4(V1.1)", "U5(V1.1)", "U6(V1.1)", "V1.1>V2.1",
         "V1.1<=V2.1+10", "V1.1==7&&I1.1", "V1.1!=7||V2.1", 'V3.1=="ab"', "S2.1", "!!(I1.1)"]


def test_compiled_expressions_table() -> None:
    from coolmuscle.cml.parser import parse
    c = chain()
    motor = c.motors[1]
    for text in TABLE:
        (line,) = parse(f"V9.1={text}")
        expr = line.statements[0].value  # type: ignore[union-attr]
        assert compile_expr(expr, motor)() == evaluate(expr, MotorEval(motor)), text


@settings(max_examples=300, deadline=None)
@given(expressions.map(_small))
def test_compiled_expressions_equal_evaluate(expr: ast.Expr) -> None:
    c = chain()
    motor = c.motors[1]
    try:
        expected: object = evaluate(expr, MotorEval(motor))
    except Exception as exc:   # noqa: BLE001 - the same failure is expected
        expected = type(exc)
    try:
        got: object = compile_expr(expr, motor)()
    except Exception as exc:   # noqa: BLE001
        got = type(exc)
    assert got == expected


_targets = st.builds(ast.Reg, st.sampled_from("PSAMTVNR"), st.integers(0, 20),
                     st.sampled_from([None, 1]))


@settings(max_examples=200, deadline=None)
@given(_targets, st.sampled_from(["=", "+=", "-="]), expressions.map(_small), st.booleans())
def test_compiled_assignments_equal_the_interpreter(target: ast.Reg, op: str, value: ast.Expr,
                                                    quiet: bool) -> None:
    stmt = ast.Assign(target, op, value)  # type: ignore[arg-type]
    results = []
    for compiled in (False, True):
        c = chain()
        seen: list[str] = []
        c.subscribe(lambda e: seen.append(e.text))  # noqa: B023 (c: this iteration's)
        runner = c.motors[1].ladder
        fn = compile_statement(stmt, c.motors[1], runner.ctx, quiet, _Clock(), _assigned)
        if compiled and fn is not None:
            fn()
        else:
            runner._assign(stmt, quiet)   # the interpreter's path
        results.append((seen, c.motors[1].memory.to_dict()))
    assert results[0] == results[1]


ASSIGNMENTS = ["V5.1=V1.1*10", "V1.1+=V2.1", "V1.1-=V2.1", "S.1=V1.1", "S0.1=V2.1*1000000",
               'V3.1="cd"', "V4.1=V1.1", "V20.1=V1.1", "K23.1=V1.1", "K23.1=V6.1", "P1.2=V1.1",
               "P1.1=V7.1", "A1.1=V2.1", "M1.1=V1.1*100"]


def test_compiled_assignments_table() -> None:
    from coolmuscle.cml.parser import parse
    for text in ASSIGNMENTS:
        (line,) = parse(text)
        results = []
        for compiled in (False, True):
            c = chain()
            seen: list[str] = []
            c.subscribe(lambda e: seen.append(e.text))  # noqa: B023 (c: this iteration's)
            runner = c.motors[1].ladder
            stmt = line.statements[0]
            fn = compile_statement(stmt, c.motors[1], runner.ctx, False, _Clock(), _assigned)
            if compiled and fn is not None:
                fn()
            else:
                runner._assign(stmt, False)  # type: ignore[arg-type]
            results.append((seen, c.motors[1].memory.to_dict(), c.motors[2].memory.to_dict(),
                            c.motors[1].k(23)))
        assert results[0] == results[1], text
