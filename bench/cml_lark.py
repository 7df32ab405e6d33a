"""A lark (LALR) grammar of CML and a transformer to coolmuscle.cml.ast.

Owns nothing in the product: it is the yardstick for bench/bench_parser.py and a
differential oracle for tests/test_cml_parser.py.  It was written from the manuals
(cml-users-guide.txt 2.1, 2.2, 6.2-6.9; cm-banks-rt3.txt 1.1-1.5, 3.3, 7), not from
the hand-written parser, and is deliberately simpler:

* blanks are ignored everywhere (so it also accepts ``P2.1 +``, ``? 96``, which the
  real parser refuses: a command and its number are one token);
* a single ``/`` is a comment when no operand follows it, wherever it stands;
* the limits (digits, motor 1..99, loop count, one Not per statement, nesting) and
  the Not-must-end-the-expression rule are not checked.

On valid lines both parsers must agree; that is what the oracle test checks.
"""

from __future__ import annotations

import re
from typing import Any

from lark import Lark, Token, Transformer, v_args

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

GRAMMAR = r"""
start: segment (SEMI segment)* SEMI?
segment: element ("," element)*
element: item (":" item)*

?item: reg ASSIGN expr        -> assign
     | reg MOD                -> ref_mod
     | OWORD "=" expr         -> output_word
     | MOVE MOD?              -> move
     | INTERP MOD?            -> interp
     | command
     | expr

command: OUTPUT | CALL | LOOP | LOOPEND | WAIT | BANK | END | GO | ORIGIN | ENABLE
       | FREE | PAUSE | STOPBANK | STOPLINE | ESTOP | NEXT | PREV | SAVE | STARTBANK
       | QUERY | CAPTURE | ALLOC

?expr: logic
?logic: compare
      | logic LOGIC_OP compare  -> logic
?compare: arith
        | arith CMP_OP arith    -> compare
?arith: term
      | arith ADD_OP term       -> binop
?term: factor
     | term MUL_OP factor       -> binop
?factor: NUMBER                 -> num
       | SIGNED                 -> num
       | STRING                 -> string
       | reg
       | INPUT                  -> input
       | FUNC "(" expr ")"      -> func
       | NOT "(" expr ")"       -> negation
reg: REG

MOTOR: /\.[0-9]+/
MOD.3: /[+-](?=[ \t]*([,:;\/]|$))/
ASSIGN: "=" | "+=" | "-="
LOGIC_OP: "&&" | "||"
CMP_OP: "==" | "!=" | ">=" | "<=" | ">" | "<"
ADD_OP: "+" | "-"
MUL_OP: "*" | DIV
DIV: "/"
NOT: "!!" | "!"
SEMI: ";"

REG.2: /[PSAMTVNRKH][0-9]*(\.[0-9]+)?(?![A-Z])/i
INPUT.2: /I[0-9]+(\.[0-9]+)?/i
FUNC.2: /U[1-6]/i
OWORD.2: /O(\.[0-9]+)?(?=[ \t]*=)/i
OUTPUT.2: /[OF][0-9]+(\.[0-9]+)?/i
MOVE.2: /[YQZ][0-9]*(\.[0-9]+)?/i
CALL.2: /(CL|JL|C|J)[0-9]+(\.[0-9]+)?/i
LOOPEND.3: /X(\.[0-9]+)?-/i
LOOP.2: /X[0-9]+(\.[0-9]+)?/i
WAIT.2: /W[0-9]+(\.[0-9]+)?/i
BANK.2: /[BL][0-9]+(\.[0-9]+)?/i
END.2: /END(\.[0-9]+)?/i
GO: /\^([0-9]+|\.[0-9]+)?/
ORIGIN: /\|([12](\.[0-9]+)?|\.[0-9]+)?/
ENABLE: /\((\.[0-9]+)?/
FREE: /\)(\.[0-9]+)?/
PAUSE: /\](1?(\.[0-9]+)?)/
STOPBANK.2: /\](LM|L)(\.[0-9]+)?/i
STOPLINE: /\}(\.[0-9]+)?/
ESTOP: /\*(1?(\.[0-9]+)?)/
NEXT: />(\.[0-9]+)?/
PREV: /<(\.[0-9]+)?/
SAVE: /\$(\.[0-9]+)?/
STARTBANK: /\[((LM|L)?[0-9]*)(\.[0-9]+)?/i
QUERY: /\?([ASMTVPNRL]?[0-9]*)(\.[0-9]+)?/i
CAPTURE: /#[0-9]+(\.[0-9]+)?/
INTERP: /@[0-9]*(\.[0-9]+)?/
ALLOC: /[\\\u00a5\u20a9][PN][0-9]+/i
NUMBER: /[0-9]+/
SIGNED: /[+-][0-9]+/
STRING: /"[ !#-~]*"/

COMMENT: /\/\/.*/
       | /\/(?![ \t]*([0-9"!]|[-+][0-9]|[PSAMTVNRKH](?![A-Z])|[IU][0-9]))(?i:.*)/i
%ignore COMMENT
%ignore /[ \t]+/
"""

_PARTS = re.compile(r"([A-Za-z]*)([0-9]*)(?:\.([0-9]+))?")
_EXEC = {"^": "go", "|": "origin", "|1": "go_origin", "|2": "set_origin", "(": "enable",
         ")": "free", "]": "pause", "]1": "pause_motor", "}": "stop_after_line",
         "*": "estop", "*1": "estop_release", ">": "next_line", "<": "prev_line",
         "$": "save"}


def _parts(text: str) -> tuple[str, int | None, int | None]:
    """``"P2.1"`` -> ("P", 2, 1); ``"END"`` -> ("END", None, None)."""
    m = _PARTS.fullmatch(text)
    assert m is not None, text
    letters, digits, motor = m.groups()
    return (letters.upper(), int(digits) if digits else None,
            int(motor) if motor else None)


def _command(tok: Token) -> Any:
    """One command token -> statement."""
    text, kind = str(tok), tok.type
    if kind in ("GO", "ORIGIN", "ENABLE", "FREE", "PAUSE", "STOPLINE", "ESTOP", "NEXT",
                "PREV", "SAVE"):
        sym, rest = text[0], text[1:]
        _, digits, motor = _parts(rest)
        if kind == "GO" and digits is not None:
            return Exec("go", digits)
        return Exec(_EXEC[sym + ("" if digits is None else str(digits))], motor)
    if kind == "LOOPEND":
        return LoopEnd(_parts(text[:-1])[2])
    letters, index, motor = _parts(text.lstrip("]#[?\\\u00a5\u20a9"))
    if kind == "STOPBANK":
        return StopBank(letters, motor)
    if kind == "STARTBANK":
        return StartBank(letters or "B", index, motor)
    if kind == "QUERY":
        return Query(index, letters or None, motor)
    if kind == "CAPTURE":
        return Capture(index, motor)
    if kind == "ALLOC":
        return Alloc(letters, index)
    if kind == "OUTPUT":
        return Output(letters == "O", index, motor)
    if kind == "CALL":
        return Call(letters, index, motor)
    if kind == "LOOP":
        return Loop(index, motor)
    if kind == "WAIT":
        return Wait(index, motor)
    if kind == "BANK":
        return (ClearBanks(letters == "L", motor) if index == 100
                else BankBegin(letters == "L", index, motor))
    if kind == "END":
        return BankEnd(motor)
    raise ValueError(kind)


@v_args(inline=True)
class ToAst(Transformer):
    """Lark tree -> ``list[Line]`` (``source`` left empty)."""

    def start(self, *parts: Any) -> list[Line]:
        lines: list[Line] = []
        for part in parts:
            if isinstance(part, Token):  # SEMI
                lines[-1] = Line(lines[-1].statements, True)
            else:
                lines.append(Line(part))
        return lines

    def segment(self, *elements: list[Any]) -> tuple[Any, ...]:
        head = elements[0]
        if len(head) == 1 and _is_condition(head[0], len(elements) > 1):
            if len(elements) > 3:
                raise ValueError("branch with more than 3 elements")
            acts = [tuple(_statement(x) for x in el) for el in elements[1:]] + [(), ()]
            return (Branch(head[0], acts[0], acts[1]),)
        if any(len(el) > 1 for el in elements):
            raise ValueError("':' outside a branch")
        return tuple(_statement(el[0]) for el in elements)

    def element(self, *items: Any) -> list[Any]:
        return list(items)

    def reg(self, tok: Token) -> Reg:
        return Reg(*_parts(str(tok)))

    def assign(self, reg: Reg, op: Token, value: Any) -> Assign:
        return Assign(reg, str(op), value)  # type: ignore[arg-type]

    def ref_mod(self, reg: Reg, mod: Token) -> Ref:
        return Ref(reg, str(mod))  # type: ignore[arg-type]

    def output_word(self, tok: Token, value: Any) -> OutputWord:
        return OutputWord(value, _parts(str(tok))[2])

    def move(self, tok: Token, mod: Token | None = None) -> Move:
        letters, index, motor = _parts(str(tok))
        return Move(letters, index, motor, str(mod) if mod else None)  # type: ignore[arg-type]

    def interp(self, tok: Token, mod: Token | None = None) -> Interp:
        _, index, motor = _parts(str(tok)[1:])
        return Interp(index, motor, str(mod) if mod else None)  # type: ignore[arg-type]

    def command(self, tok: Token) -> Any:
        return _command(tok)

    def logic(self, left: Any, op: Token, right: Any) -> Logic:
        return Logic(str(op), left, right)  # type: ignore[arg-type]

    def compare(self, left: Any, op: Token, right: Any) -> Compare:
        return Compare(str(op), left, right)  # type: ignore[arg-type]

    def binop(self, left: Any, op: Token, right: Any) -> BinOp:
        return BinOp(str(op), left, right)  # type: ignore[arg-type]

    def num(self, tok: Token) -> Num:
        return Num(int(str(tok)))

    def string(self, tok: Token) -> Str:
        return Str(str(tok)[1:-1])

    def input(self, tok: Token) -> Input:
        _, index, motor = _parts(str(tok))
        return Input(index, motor)  # type: ignore[arg-type]

    def func(self, name: Token, arg: Any) -> Func:
        return Func(str(name).upper(), arg)  # type: ignore[arg-type]

    def negation(self, _bang: Token, operand: Any) -> Not:
        return Not(operand)


_CONDITIONS = (Compare, Logic, Not, Input)
_EXPRESSIONS = (Num, Str, Reg, Input, BinOp, Func, Compare, Logic, Not)


def _is_condition(item: Any, more: bool) -> bool:
    return isinstance(item, _CONDITIONS) or (
        more and isinstance(item, Reg) and item.kind == "V")


def _statement(item: Any) -> Any:
    if isinstance(item, Reg):
        return Ref(item)
    if isinstance(item, _EXPRESSIONS):
        raise ValueError(f"expression where a statement is expected: {item!r}")
    return item


def make_parser() -> Lark:
    """The LALR parser (contextual lexer), built once."""
    return Lark(GRAMMAR, parser="lalr", lexer="contextual", maybe_placeholders=False)


class LarkCml:
    """``parse(text) -> list[Line]`` like :func:`coolmuscle.cml.parse` (no ``source``)."""

    def __init__(self) -> None:
        self.lark = make_parser()
        self.to_ast = ToAst()

    def parse(self, text: str) -> list[Line]:
        return self.to_ast.transform(self.lark.parse(text))
