"""The CML parser: one physical line of text -> ``list[Line]`` (:mod:`coolmuscle.cml.ast`).

This module owns CML *syntax*: what a line means is the executor's business, what
it *says* is decided here.  It is used for the host line, bank uploads,
``coolmuscle check`` and the client (docs/architecture.md, rule 3).

Two passes, both hand-written: :func:`coolmuscle.cml.scanner.scan` turns the text
into tokens (and finds the comment), then the recursive-descent :class:`_Parser`
here builds the tree: segments split by ``;``, statements split by ``,``, branches
``condition, then, else`` with ``:`` junctions, and expressions with the usual
precedence (``* /`` over ``+ -`` over comparisons over ``&& ||``).

Anything that does not parse raises :class:`~coolmuscle.errors.CmlSyntaxError`
with the 0-based column of the offending character; no other exception escapes
:func:`parse` for any ``str``.  The choices where the manuals are silent are
listed in docs/fidelity.md, "CML language".
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final, NoReturn

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
from coolmuscle.cml.scanner import MAX_INDEX, MAX_LOOP, MAX_MOTOR, Tok, fail, scan

__all__ = ["parse"]

_REGISTERS: Final = frozenset(REGISTER_KINDS)
_QUERY_LETTERS: Final = frozenset("ASMTVPNRL")
_SEPARATORS: Final = frozenset({",", ":", ";", "eof"})
_SEGMENT_END: Final = frozenset({";", "eof"})
_ASSIGN_OPS: Final = frozenset({"=", "+=", "-="})
_COMPARE_OPS: Final = frozenset({"==", "!=", ">", ">=", "<", "<="})
_LOGIC_OPS: Final = frozenset({"&&", "||"})
_ADD_OPS: Final = frozenset({"+", "-"})
_MUL_OPS: Final = frozenset({"*", "/"})
_NOT_OPS: Final = frozenset({"!", "!!"})
_CONDITIONS: Final = (Compare, Logic, Not, Input)
_EXPRESSIONS: Final = (Num, Str, Reg, Input, BinOp, Func, Compare, Logic, Not)
_SIMPLE_EXEC: Final = {"(": "enable", ")": "free", "}": "stop_after_line",
                       ">": "next_line", "<": "prev_line", "$": "save"}


def parse(text: str) -> list[Line]:
    """Parse one physical line (without CR/LF) into its logical lines.

    Returns ``[]`` for a blank or comment-only line.  A ``;`` splits the line;
    every Line followed by a ``;`` has ``joined=True`` (cml-users-guide.txt 2.2.2
    "; (semi colon)").  ``Line.source`` is the text of that Line without comment,
    ``;`` and surrounding blanks.
    """
    toks, code_end = scan(text)
    if len(toks) == 1:
        return []
    return _Parser(text, toks).lines(code_end)


class _Parser:
    """Recursive descent over the tokens of one physical line."""

    __slots__ = ("text", "toks", "i", "tok")

    def __init__(self, text: str, toks: list[Tok]) -> None:
        self.text, self.toks, self.i, self.tok = text, toks, 0, toks[0]

    # ------------------------------------------------------------ helpers
    def fail(self, message: str, position: int) -> NoReturn:
        fail(self.text, message, position)

    def unexpected(self, tok: Tok | None = None) -> NoReturn:
        tok = tok or self.tok
        if tok.kind == "eof":
            self.fail("unexpected end of line", tok.start)
        self.fail(f"unexpected {self.text[tok.start:tok.end]!r}", tok.start)

    def advance(self) -> Tok:
        tok = self.tok
        self.i += 1
        self.tok = self.toks[self.i]
        return tok

    def expect(self, kind: str) -> Tok:
        if self.tok.kind != kind:
            if self.tok.kind == "eof":
                self.fail(f"expected {kind!r}", self.tok.start)
            self.unexpected()
        return self.advance()

    def attached(self, prev: Tok, *kinds: str) -> Tok | None:
        """Consume and return the next token if it touches ``prev`` and is of ``kinds``."""
        tok = self.tok
        if tok.start == prev.end and tok.kind in kinds:
            return self.advance()
        return None

    def modifier(self, prev: Tok) -> str | None:
        """A ``+``/``-`` written right after ``prev`` and ending the statement."""
        tok = self.tok
        if (tok.kind in _ADD_OPS and tok.start == prev.end
                and self.toks[self.i + 1].kind in _SEPARATORS):
            return self.advance().kind
        return None

    def motor_suffix(self, prev: Tok) -> int | None:
        """An optional ``.n`` written right after a command symbol."""
        tok = self.attached(prev, "mot")
        return None if tok is None else tok.motor

    def no_motor(self, tok: Tok) -> None:
        if tok.motor is not None:
            self.fail("no motor ID allowed here", tok.mpos)

    def no_index(self, tok: Tok) -> None:
        if tok.val is not None:
            self.fail(f"{tok.text} takes no number", tok.ipos)

    def index(self, tok: Tok, what: str = "number", top: int = MAX_INDEX) -> int:
        """The required number of ``tok`` (a word's index or a num's value)."""
        if tok.val is None:
            self.fail(f"missing {what} after {tok.text}", tok.end)
        if tok.val > top:
            self.fail(f"{what} must be 0..{top}", tok.ipos)
        return tok.val

    def opt_index(self, tok: Tok) -> int | None:
        return None if tok.val is None else self.index(tok)

    # ------------------------------------------------------------- lines
    def lines(self, code_end: int) -> list[Line]:
        """Segments separated by ``;`` -> Lines (cml-users-guide.txt 2.2.2 ";")."""
        out: list[Line] = []
        begin = 0
        while True:
            if self.tok.kind == ";":
                self.fail("nothing before ';'", self.tok.start)
            statements = self.segment()
            if self.tok.kind == ";":
                semi = self.advance()
                out.append(Line(statements, True, self.text[begin:semi.start].strip(" \t")))
                if self.tok.kind == "eof":
                    return out
                begin = semi.end
            else:
                out.append(Line(statements, False, self.text[begin:code_end].strip(" \t")))
                return out

    def segment(self) -> tuple[Statement, ...]:
        """Comma-separated statements, or one branch (cml-users-guide.txt 4.2.2)."""
        first = self.tok
        head = self.head()
        if isinstance(head, _EXPRESSIONS):
            return (self.branch(head, first),)
        statements = [head]
        while self.tok.kind == ",":
            self.advance()
            statements.append(self.statement())
        self.end_of_segment()
        return tuple(statements)

    def end_of_segment(self) -> None:
        if self.tok.kind not in _SEGMENT_END:
            if self.tok.kind == ":":
                self.fail("':' joins actions of a branch only", self.tok.start)
            self.unexpected()

    def branch(self, condition: Expr, first: Tok) -> Branch:
        """``condition, then, else``; then/else are ``:``-joined (6.3 "I", "V")."""
        if self.tok.kind not in (",", ";", "eof"):
            self.end_of_segment()
        if not (isinstance(condition, _CONDITIONS)
                or (isinstance(condition, Reg) and condition.kind == "V")):
            self.fail("not a condition (use I#, V#, a comparison or && || !!)", first.start)
        parts: list[tuple[Statement, ...]] = []
        while self.tok.kind == ",":
            comma = self.advance()
            if len(parts) == 2:
                self.fail("a branch has at most 3 elements: condition, then, else",
                          comma.start)
            parts.append(self.actions())
        self.end_of_segment()
        if not parts and self.tok.kind == "eof":
            self.fail("condition without action (join the next line with ';')",
                      self.tok.start)
        then = parts[0] if parts else ()
        return Branch(condition, then, parts[1] if len(parts) > 1 else ())

    def actions(self) -> tuple[Statement, ...]:
        """Statements joined by ``:`` (cml-users-guide.txt 2.2.2 ": (colon)")."""
        acts = [self.statement()]
        while self.tok.kind == ":":
            self.advance()
            acts.append(self.statement())
        return tuple(acts)

    # -------------------------------------------------------- statements
    def head(self) -> Statement | Expr:
        """The first element of a segment: a statement or a branch condition."""
        tok = self.tok
        kind = tok.kind
        if kind == "word":
            if tok.text in _REGISTERS:
                return self.register_statement(tok, head=True)
            if tok.text in ("I", "U"):
                return self.expression()
            return self.word_statement(tok)
        if kind in ("num", "str", "+", "-", "!", "!!"):
            return self.expression()
        return self.symbol_statement(tok)

    def statement(self) -> Statement:
        """A statement after a ``,`` or ``:``."""
        tok = self.tok
        if tok.kind == "word":
            if tok.text in _REGISTERS:
                return self.register_statement(tok, head=False)  # type: ignore[return-value]
            if tok.text in ("I", "U"):
                self.fail("a condition must be the first element of a line", tok.start)
            return self.word_statement(tok)
        return self.symbol_statement(tok)

    def register_statement(self, tok: Tok, head: bool) -> Statement | Expr:
        """``P1.1=...`` Assign, ``P2.1+`` / ``V2.1`` Ref, or (head) a condition."""
        reg = Reg(tok.text, self.opt_index(tok), tok.motor)
        nxt = self.toks[self.i + 1]
        if nxt.kind in _ASSIGN_OPS:
            self.advance()
            op = self.advance().kind
            return Assign(reg, op, self.expression())  # type: ignore[arg-type]
        if nxt.kind in _SEPARATORS:
            self.advance()
            if head and nxt.kind == "," and reg.kind == "V":
                return reg  # "V alone means V > 0" (6.3 "V")
            return Ref(reg)
        if (nxt.kind in _ADD_OPS and nxt.start == tok.end
                and self.toks[self.i + 2].kind in _SEPARATORS):
            self.advance()
            self.advance()
            return Ref(reg, nxt.kind)  # type: ignore[arg-type]
        if head:
            return self.expression()
        if nxt.kind in _COMPARE_OPS or nxt.kind in _LOGIC_OPS:
            self.fail("a condition must be the first element of a line", tok.start)
        self.unexpected(nxt)

    def word_statement(self, tok: Tok) -> Statement:
        """Letter commands: Y Q Z O F C J CL JL X W B L END (2.2.2, 2.2.3)."""
        word = tok.text
        self.advance()
        if word in ("Y", "Q", "Z"):
            mod = self.modifier(tok)
            return Move(word, self.opt_index(tok), tok.motor, mod)  # type: ignore[arg-type]
        if word == "O" and tok.val is None:
            self.expect("=")
            return OutputWord(self.expression(), tok.motor)
        if word in ("O", "F"):
            return Output(word == "O", self.index(tok, "output number"), tok.motor)
        if word in ("C", "J", "CL", "JL"):
            return Call(word, self.index(tok, "bank number"), tok.motor)  # type: ignore[arg-type]
        if word == "X":
            return self.loop(tok)
        if word == "W":
            return Wait(self.index(tok, "timer number"), tok.motor)
        if word in ("B", "L"):
            number = self.index(tok, "bank number")
            if number == 100:
                return ClearBanks(word == "L", tok.motor)
            return BankBegin(word == "L", number, tok.motor)
        if word == "END":
            self.no_index(tok)
            return BankEnd(tok.motor)
        self.fail(f"unknown command {self.text[tok.start:tok.ipos]!r}", tok.start)

    def loop(self, tok: Tok) -> Loop | LoopEnd:
        """``X#.n`` loop count 0..255, ``X.n-`` end of loop (2.2.2 "X")."""
        if tok.val is None:
            if self.modifier(tok) != "-":
                self.fail("X needs a loop count, or '-' to end the loop", tok.end)
            return LoopEnd(tok.motor)
        return Loop(self.index(tok, "loop count", MAX_LOOP), tok.motor)

    def symbol_statement(self, tok: Tok) -> Statement:
        """Execution commands and queries (2.1.2, 6.5, 6.6)."""
        method = _SYMBOL_METHODS.get(tok.kind)
        if method is None:
            self.unexpected(tok)
        self.advance()
        return method(self, tok)

    def simple(self, tok: Tok) -> Exec:
        """``( ) } > < $`` with an optional ``.n`` (2.1.2)."""
        return Exec(_SIMPLE_EXEC[tok.kind], self.motor_suffix(tok))  # type: ignore[arg-type]

    def go(self, tok: Tok) -> Exec:
        """``^.n``; ``^1`` as written in 2.2.3 is read as ``^.1``."""
        num = self.attached(tok, "num")
        if num is not None:
            self.no_motor(num)
            if not 1 <= num.val <= MAX_MOTOR:  # type: ignore[operator]
                self.fail(f"motor ID must be 1..{MAX_MOTOR}", num.start)
            return Exec("go", num.val)
        return Exec("go", self.motor_suffix(tok))

    def digit_exec(self, tok: Tok, ops: dict[int, str], plain: str) -> Exec:
        """``|`` ``|1`` ``|2``, ``*`` ``*1``, ``]`` ``]1`` with optional ``.n``."""
        num = self.attached(tok, "num")
        if num is None:
            return Exec(plain, self.motor_suffix(tok))  # type: ignore[arg-type]
        if num.val not in ops:
            self.fail(f"{tok.kind}{num.val} is not a command", num.start)
        return Exec(ops[num.val], num.motor)  # type: ignore[arg-type]

    def origin(self, tok: Tok) -> Exec:
        return self.digit_exec(tok, {1: "go_origin", 2: "set_origin"}, "origin")

    def estop(self, tok: Tok) -> Exec:
        return self.digit_exec(tok, {1: "estop_release"}, "estop")

    def pause(self, tok: Tok) -> Exec | StopBank:
        """``]`` ``]1.n`` pause, ``]L.n`` ``]LM.n`` stop a ladder bank (6.5)."""
        word = self.attached(tok, "word")
        if word is None:
            return self.digit_exec(tok, {1: "pause_motor"}, "pause")
        if word.text not in ("L", "LM"):
            self.unexpected(word)
        self.no_index(word)
        return StopBank(word.text, word.motor)  # type: ignore[arg-type]

    def start_bank(self, tok: Tok) -> StartBank:
        """``[#.n``, ``[`` (resume), ``[L#.n``, ``[LM#.n`` (6.5, RT3 3.2)."""
        nxt = self.attached(tok, "num", "mot", "word")
        if nxt is None:
            return StartBank("B")
        if nxt.kind == "word" and nxt.text not in ("L", "LM"):
            self.unexpected(nxt)
        kind = nxt.text if nxt.kind == "word" else "B"
        return StartBank(kind, self.opt_index(nxt), nxt.motor)  # type: ignore[arg-type]

    def query(self, tok: Tok) -> Query:
        """``?``, ``?.n``, ``?#.n``, ``?A.n`` ... ``?L#.n`` (6.6)."""
        nxt = self.attached(tok, "num", "mot", "word")
        if nxt is None:
            return Query()
        if nxt.kind == "word" and nxt.text not in _QUERY_LETTERS:
            self.fail(f"unknown query ?{self.text[nxt.start:nxt.ipos]}", nxt.start)
        letter = nxt.text if nxt.kind == "word" else None
        return Query(self.opt_index(nxt), letter, nxt.motor)

    def capture(self, tok: Tok) -> Capture:
        """``#x.n``: capture the position into P memory x (2.1.2 "#")."""
        num = self.attached(tok, "num")
        if num is None:
            self.fail("# needs a P memory number", tok.end)
        return Capture(self.index(num, "P memory number"), num.motor)

    def interp(self, tok: Tok) -> Interp:
        """``@#.n+`` / ``@.n-`` / ``@#.n`` (2.1.2 "@")."""
        nxt = self.attached(tok, "num", "mot") or tok
        if nxt is tok:
            return Interp(None, None, self.modifier(tok))  # type: ignore[arg-type]
        return Interp(self.opt_index(nxt), nxt.motor, self.modifier(nxt))  # type: ignore[arg-type]

    def alloc(self, tok: Tok) -> Alloc:
        r"""``\P300`` / ``\N200`` (2.1.2 "\\"; also written with the yen sign)."""
        word = self.attached(tok, "word")
        if word is None or word.text not in ("P", "N"):
            self.fail("\\ must be followed by P# or N#", tok.end)
        self.no_motor(word)
        return Alloc(word.text, self.index(word, "count"))  # type: ignore[arg-type]

    # ------------------------------------------------------- expressions
    def expression(self) -> Expr:
        """Logic ``&&`` ``||``: one level, left to right (6.8)."""
        left = self.comparison()
        while self.tok.kind in _LOGIC_OPS:
            op = self.advance().kind
            left = Logic(op, left, self.comparison())  # type: ignore[arg-type]
        return left

    def comparison(self) -> Expr:
        """``a == b`` etc. (6.9); comparisons do not chain."""
        left = self.arithmetic()
        if self.tok.kind in _COMPARE_OPS:
            op = self.advance().kind
            left = Compare(op, left, self.arithmetic())  # type: ignore[arg-type]
            if self.tok.kind in _COMPARE_OPS:
                self.fail("comparisons cannot be chained", self.tok.start)
        return left

    def arithmetic(self) -> Expr:
        """``+ -`` over terms, left-associative (6.7)."""
        left = self.term()
        while self.tok.kind in _ADD_OPS:
            op = self.advance().kind
            left = BinOp(op, left, self.term())  # type: ignore[arg-type]
        return left

    def term(self) -> Expr:
        """``* /`` over primaries, binding tighter than ``+ -`` (6.7)."""
        left = self.primary()
        while self.tok.kind in _MUL_OPS:
            op = self.advance().kind
            left = BinOp(op, left, self.primary())  # type: ignore[arg-type]
        return left

    def primary(self) -> Expr:
        """Number, string, register, ``I#``, ``U#(...)`` or ``!!(...)``."""
        tok = self.tok
        kind = tok.kind
        if kind == "num":
            self.advance()
            self.no_motor(tok)
            return Num(tok.val)  # type: ignore[arg-type]
        if kind == "word":
            return self.operand_word(tok)
        if kind == "str":
            self.advance()
            return Str(tok.text)
        if kind in _ADD_OPS:
            self.advance()
            num = self.attached(tok, "num")
            if num is None:
                self.fail(f"'{kind}' must be followed by a number", tok.end)
            self.no_motor(num)
            return Num(-num.val if kind == "-" else num.val)  # type: ignore[operator,arg-type]
        if kind in _NOT_OPS:
            return self.negation()
        if kind == "eof":
            self.fail("expected an operand", tok.start)
        self.unexpected(tok)

    def operand_word(self, tok: Tok) -> Expr:
        word = tok.text
        self.advance()
        if word in _REGISTERS:
            return Reg(word, self.opt_index(tok), tok.motor)
        if word == "I":
            return Input(self.index(tok, "input number"), tok.motor)
        if word == "U" and tok.val is not None and 1 <= tok.val <= 6:
            self.no_motor(tok)
            self.expect("(")
            arg = self.expression()
            self.expect(")")
            return Func(f"U{tok.val}", arg)  # type: ignore[arg-type]
        self.fail(f"unknown operand {self.text[tok.start:tok.end]!r}", tok.start)

    def negation(self) -> Not:
        """``!!(x)`` or ``!(x)``, followed by ``,`` or the end (6.8)."""
        self.advance()
        self.expect("(")
        operand = self.expression()
        self.expect(")")
        if self.tok.kind not in _SEPARATORS:
            self.fail("'!!(...)' must be followed by ','", self.tok.start)
        return Not(operand)


_SYMBOL_METHODS: Final[dict[str, Callable[[_Parser, Tok], Statement]]] = {
    "^": _Parser.go, "|": _Parser.origin, "*": _Parser.estop, "]": _Parser.pause,
    "[": _Parser.start_bank, "?": _Parser.query, "#": _Parser.capture,
    "@": _Parser.interp, "\\": _Parser.alloc, "(": _Parser.simple, ")": _Parser.simple,
    "}": _Parser.simple, ">": _Parser.simple, "<": _Parser.simple, "$": _Parser.simple,
}
