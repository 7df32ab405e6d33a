"""Expression and condition evaluation (cml-users-guide.txt 6.7–6.9; cm-banks-rt3.txt 1.4–1.5).

CML is integer-only.  Arithmetic runs in signed 32-bit like the motor's long type
(results wrap); ``/`` truncates toward zero and a division by zero gives 0; a
comparison or logical operator gives 1 (true) or 0 (false).  A V register holding a
string compares by its characters (packed into an integer); a V register bound to a
state ("Px", "Ix", ...) is read live.  All choices are in docs/fidelity.md.

The evaluator reads through :class:`EvalHost`, which the motor implements, so the
same code serves direct mode, program banks and ladder banks.
"""

from __future__ import annotations

import math
from typing import Protocol

from ...cml import ast

INT32_MIN = -(2 ** 31)
INT32_MAX = 2 ** 31 - 1


def wrap32(value: int) -> int:
    """Wrap to the signed 32-bit range of the motor's long type."""
    value &= 0xFFFFFFFF
    return value - 0x1_0000_0000 if value & 0x8000_0000 else value


def pack_string(text: str) -> int:
    """A V string (up to 4 characters) as the integer its bytes form (big-endian)."""
    value = 0
    for ch in text[:4]:
        value = (value << 8) | (ord(ch) & 0xFF)
    return wrap32(value)


class EvalHost(Protocol):
    """What the evaluator needs from the motor (and, through it, the chain)."""

    def register_value(self, reg: ast.Reg) -> int:
        """Numeric value of a register (V strings packed, V states read live)."""

    def input_signal(self, number: int, motor: int | None) -> bool:
        """Logical input signal (after K26) of ``motor`` (None = this motor)."""

    def table(self, kind: str, index: int) -> int:
        """N or R memory value for U4/U5/U6."""

    def sine(self, x: int) -> int:
        """U1 with the firmware's angle scaling (CML 0.01 degree, RT3 1/10000 turn)."""

    def cosine(self, x: int) -> int:
        """U2 with the firmware's angle scaling."""


def _trunc(x: float) -> int:
    """Truncate toward zero."""
    return int(round(x, 6))


def _lookup(host: EvalHost, x: int) -> int:
    """U4: find x among N1.. and return the matching R (linear between entries)."""
    points = []
    for i in range(1, 26):
        try:
            points.append((host.table("N", i), host.table("R", i)))
        except (IndexError, LookupError, ValueError):
            break
    if not points:
        return 0
    for n, r in points:
        if n == x:
            return r
    points.sort()
    if x <= points[0][0]:
        return points[0][1]
    if x >= points[-1][0]:
        return points[-1][1]
    for (n0, r0), (n1, r1) in zip(points, points[1:]):
        if n0 <= x <= n1 and n1 != n0:
            return _trunc(r0 + (r1 - r0) * (x - n0) / (n1 - n0))
    return 0


def _polynomial(host: EvalHost, kind: str, x: int) -> int:
    """U5/U6: order in N0/R0, coefficients N1../R1.. of x^0, x^1, ..."""
    order = max(0, min(host.table(kind, 0), 25))
    total = 0
    for i in range(order):
        total += host.table(kind, i + 1) * x ** i
    return wrap32(total)


def call_function(name: str, x: int, host: EvalHost) -> int:
    """U1..U6 (6.7; cm-banks-rt3.txt 1.5 advanced math functions)."""
    if name == "U1":
        return host.sine(x)
    if name == "U2":
        return host.cosine(x)
    if name == "U3":
        return math.isqrt(x) if x > 0 else 0
    if name == "U4":
        return _lookup(host, x)
    if name == "U5":
        return _polynomial(host, "N", x)
    if name == "U6":
        return _polynomial(host, "R", x)
    raise ValueError(f"unknown function {name}")


def _arith(op: str, a: int, b: int) -> int:
    if op == "+":
        return wrap32(a + b)
    if op == "-":
        return wrap32(a - b)
    if op == "*":
        return wrap32(a * b)
    if b == 0:
        return 0
    q = abs(a) // abs(b)
    return wrap32(q if (a >= 0) == (b >= 0) else -q)


_COMPARE = {
    "==": lambda a, b: a == b, "!=": lambda a, b: a != b,
    ">": lambda a, b: a > b, ">=": lambda a, b: a >= b,
    "<": lambda a, b: a < b, "<=": lambda a, b: a <= b,
}


def evaluate(expr: ast.Expr, host: EvalHost) -> int:
    """Value of ``expr`` as a signed 32-bit integer."""
    if isinstance(expr, ast.Num):
        return wrap32(expr.value)
    if isinstance(expr, ast.Reg):
        return host.register_value(expr)
    if isinstance(expr, ast.Input):
        return int(host.input_signal(expr.index, expr.motor))
    if isinstance(expr, ast.BinOp):
        return _arith(expr.op, evaluate(expr.left, host), evaluate(expr.right, host))
    if isinstance(expr, ast.Func):
        return call_function(expr.name, evaluate(expr.arg, host), host)
    if isinstance(expr, ast.Compare):
        return int(_COMPARE[expr.op](evaluate(expr.left, host), evaluate(expr.right, host)))
    if isinstance(expr, ast.Logic):
        left = evaluate(expr.left, host) != 0
        right = evaluate(expr.right, host) != 0
        return int(left and right) if expr.op == "&&" else int(left or right)
    if isinstance(expr, ast.Not):
        return int(evaluate(expr.operand, host) == 0)
    if isinstance(expr, ast.Str):
        return pack_string(expr.text)
    raise TypeError(f"not an expression: {expr!r}")


def condition(expr: ast.Expr, host: EvalHost) -> bool:
    """Truth of a branch condition: a bare V or value means "> 0" (2.2.2 "V", 6.3)."""
    if isinstance(expr, (ast.Reg, ast.Num, ast.BinOp, ast.Func)):
        return evaluate(expr, host) > 0
    return evaluate(expr, host) != 0
