"""The CML parser: one physical line of text -> ``list[Line]`` (:mod:`coolmuscle.cml.ast`).

This module owns CML *syntax*: what a line means is the executor's business, what
it *says* is decided here.  It is used for the host line, bank uploads,
``coolmuscle check`` and the client (docs/architecture.md, rule 3).

Two passes, both hand-written:

* a scanner (:func:`_scan`) turns the text into tokens with one compiled regular
  expression, decides whether a ``/`` is a division or starts a comment, and
  enforces the one-Not-per-statement rule (cml-users-guide.txt 6.8);
* a recursive-descent parser (:class:`_Parser`) builds the tree.

Anything that does not parse raises :class:`~coolmuscle.errors.CmlSyntaxError`
with the 0-based column of the offending character; no other exception escapes
:func:`parse` for any ``str``.  The choices where the manuals are silent are
listed in docs/fidelity.md, "CML language".
"""

from __future__ import annotations

import re
from typing import Final, NoReturn

from coolmuscle.cml.ast import (
    REGISTER_KINDS, Alloc, Assign, BankBegin, BankEnd, BinOp, Branch, Call, Capture,
    ClearBanks, Compare, Exec, Expr, Func, Input, Interp, Line, Logic, Loop, LoopEnd,
    Move, Not, Num, Output, OutputWord, Query, Ref, Reg, StartBank, Statement, StopBank,
    Str, Wait,
)
from coolmuscle.errors import CmlSyntaxError

__all__ = ["parse", "MAX_NUMBER_DIGITS", "MAX_INDEX", "MAX_MOTOR", "MAX_LOOP"]

#: Longest digit run accepted anywhere (data range is +-1,000,000,000).
MAX_NUMBER_DIGITS: Final = 10
#: Largest memory / bank / output / query number (``?1000`` is the largest used).
MAX_INDEX: Final = 9999
#: Motor IDs the parser accepts after the dot (the executor checks 1..15).
MAX_MOTOR: Final = 99
#: Largest loop count ``X#`` (cml-users-guide.txt 2.2.2 "X": 0 ~ 255).
MAX_LOOP: Final = 255

# One token per match; leading blanks are skipped.  Outer groups W N M S O name the
# token kind (``lastgroup`` is the outermost group, which closes last).
_TOKEN_RE: Final = re.compile(
    r"""[ \t]*(?:
      (?P<W>(?P<w>[A-Za-z]+)(?P<wi>[0-9]+)?(?:\.(?P<wm>[0-9]+))?)
    | (?P<N>(?P<n>[0-9]+)(?:\.(?P<nm>[0-9]+))?)
    | (?P<M>\.(?P<m>[0-9]+))
    | (?P<S>"(?P<s>[ !\#-~]*)")
    | (?P<O>==|!=|>=|<=|&&|\|\||\+=|-=|!!|//|[-+*/=<>!(),:;^|\[\]}$?\#@\\\u00a5\u20a9])
    )""",
    re.VERBOSE,
)
_BLANKS_RE: Final = re.compile(r"[ \t]*")
# What can start an operand (the FIRST set of _Parser._primary): a single "/"
# followed by one of these is a division, otherwise it starts a comment.
_OPERAND_START_RE: Final = re.compile(
    r"[ \t]*(?:[0-9\"!]|[-+][0-9]|[PSAMTVNRKHpsamtvnrkh](?![A-Za-z])|[IiUu][0-9])"
)

_REGISTERS: Final = frozenset(REGISTER_KINDS)
_QUERY_LETTERS: Final = frozenset("ASMTVPNRL")
_SEPARATORS: Final = frozenset({",", ":", ";", "eof"})
_SEGMENT_END: Final = frozenset({";", "eof"})
_OPERAND_END: Final = frozenset({"word", "num", "str", ")"})
_ASSIGN_OPS: Final = frozenset({"=", "+=", "-="})
_COMPARE_OPS: Final = frozenset({"==", "!=", ">", ">=", "<", "<="})
_LOGIC_OPS: Final = frozenset({"&&", "||"})
_ADD_OPS: Final = frozenset({"+", "-"})
_MUL_OPS: Final = frozenset({"*", "/"})
_NOT_OPS: Final = frozenset({"!", "!!"})
_BACKSLASHES: Final = {"\\": "\\", "\u00a5": "\\", "\u20a9": "\\"}  # \, yen, won
_CONDITIONS: Final = (Compare, Logic, Not, Input)
_EXPRESSIONS: Final = (Num, Str, Reg, Input, BinOp, Func, Compare, Logic, Not)
_SIMPLE_EXEC: Final = {"(": "enable", ")": "free", "}": "stop_after_line",
                       ">": "next_line", "<": "prev_line", "$": "save"}


class _Tok:
    """One token.  ``kind`` is "word", "num", "mot", "str", "eof" or the operator text.

    word: ``text`` = letters (upper case), ``val`` = index, ``ipos`` its column;
    num: ``val`` = value; word/num/mot: ``motor`` and ``mpos`` (column of the dot).
    """

    __slots__ = ("kind", "start", "end", "text", "val", "motor", "ipos", "mpos")

    def __init__(self, kind: str, start: int, end: int, text: str = "",
                 val: int | None = None, motor: int | None = None,
                 ipos: int = 0, mpos: int = 0) -> None:
        self.kind, self.start, self.end, self.text = kind, start, end, text
        self.val, self.motor, self.ipos, self.mpos = val, motor, ipos, mpos


def _fail(text: str, message: str, position: int) -> NoReturn:
    raise CmlSyntaxError(message, text=text, position=position)


def _number(text: str, digits: str | None, pos: int) -> int | None:
    """Digits -> int, refusing runs longer than :data:`MAX_NUMBER_DIGITS`."""
    if digits is None:
        return None
    if len(digits) > MAX_NUMBER_DIGITS:
        _fail(text, f"number longer than {MAX_NUMBER_DIGITS} digits", pos)
    return int(digits)


def _motor(text: str, digits: str | None, dot: int) -> int | None:
    """The motor ID after a dot: 1..99 (cml-users-guide.txt 2.1 ".n")."""
    value = _number(text, digits, dot + 1)
    if value is not None and not 1 <= value <= MAX_MOTOR:
        _fail(text, f"motor ID must be 1..{MAX_MOTOR}", dot + 1)
    return value


def _bad_character(text: str, pos: int) -> NoReturn:
    char = text[pos]
    if char == '"':
        close = text.find('"', pos + 1)
        if close < 0:
            _fail(text, "unterminated string", pos)
        bad = next((i for i in range(pos + 1, close) if not " " <= text[i] <= "~"), pos)
        _fail(text, f"invalid character {text[bad]!r} in string", bad)
    if char == ".":
        _fail(text, "'.' must be followed by a motor ID", pos)
    _fail(text, f"invalid character {char!r}", pos)


def _scan(text: str) -> tuple[list[_Tok], int]:
    """Tokens of ``text`` up to its comment, ending with an "eof" token.

    Returns the tokens and the column where the code ends (comment start or
    length).  ``//`` always starts a comment; a single ``/`` is a division only
    after an operand and before something that can start one (RT3 1.1 "/").
    """
    toks: list[_Tok] = []
    append = toks.append
    match = _TOKEN_RE.match
    pos, size, nots, last = 0, len(text), 0, ""
    while pos < size:
        m = match(text, pos)
        if m is None:
            pos = _BLANKS_RE.match(text, pos).end()
            if pos < size:
                _bad_character(text, pos)
            break
        kind = m.lastgroup
        start, pos = m.start(kind), m.end()
        if kind == "W":
            letters_end, dot = m.end("w"), m.start("wm") - 1
            tok = _Tok("word", start, pos, m.group("w").upper(),
                       _number(text, m.group("wi"), letters_end),
                       _motor(text, m.group("wm"), dot), letters_end, dot)
        elif kind == "N":
            dot = m.start("nm") - 1
            tok = _Tok("num", start, pos, "", _number(text, m.group("n"), start),
                       _motor(text, m.group("nm"), dot), start, dot)
        elif kind == "M":
            tok = _Tok("mot", start, pos, "", None, _motor(text, m.group("m"), start),
                       start, start)
        elif kind == "S":
            tok = _Tok("str", start, pos, m.group("s"))
        else:
            op = _BACKSLASHES.get(m.group("O"), m.group("O"))
            if op == "//" or (op == "/" and not (
                    last in _OPERAND_END and _OPERAND_START_RE.match(text, pos))):
                return _finish(toks, start)
            if op in _NOT_OPS:
                nots += 1
                if nots > 1:
                    _fail(text, "only one Not operator is allowed in a statement", start)
            elif op in (",", ":", ";"):
                nots = 0
            tok = _Tok(op, start, pos)
        append(tok)
        last = tok.kind
    return _finish(toks, size)


def _finish(toks: list[_Tok], code_end: int) -> tuple[list[_Tok], int]:
    end = toks[-1].end if toks else 0
    toks.append(_Tok("eof", end, end))
    return toks, code_end


def parse(text: str) -> list[Line]:
    """Parse one physical line (without CR/LF) into its logical lines.

    Returns ``[]`` for a blank or comment-only line.  A ``;`` splits the line;
    every Line followed by a ``;`` has ``joined=True`` (cml-users-guide.txt 2.2.2
    "; (semi colon)").  ``Line.source`` is the text of that Line without comment,
    ``;`` and surrounding blanks.
    """
    toks, code_end = _scan(text)
    if len(toks) == 1:
        return []
    return _Parser(text, toks).lines(code_end)


class _Parser:
    """Recursive descent over the tokens of one physical line."""

    __slots__ = ("text", "toks", "i", "tok")

    def __init__(self, text: str, toks: list[_Tok]) -> None:
        self.text, self.toks, self.i, self.tok = text, toks, 0, toks[0]

    # ------------------------------------------------------------ helpers
    def fail(self, message: str, position: int) -> NoReturn:
        _fail(self.text, message, position)

    def unexpected(self, tok: _Tok | None = None) -> NoReturn:
        tok = tok or self.tok
        if tok.kind == "eof":
            self.fail("unexpected end of line", tok.start)
        self.fail(f"unexpected {self.text[tok.start:tok.end]!r}", tok.start)

    def advance(self) -> _Tok:
        tok = self.tok
        self.i += 1
        self.tok = self.toks[self.i]
        return tok

    def expect(self, kind: str) -> _Tok:
        if self.tok.kind != kind:
            if self.tok.kind == "eof":
                self.fail(f"expected {kind!r}", self.tok.start)
            self.unexpected()
        return self.advance()

    def attached(self, prev: _Tok, *kinds: str) -> _Tok | None:
        """Consume and return the next token if it touches ``prev`` and is of ``kinds``."""
        tok = self.tok
        if tok.start == prev.end and tok.kind in kinds:
            return self.advance()
        return None

    def modifier(self, prev: _Tok) -> str | None:
        """A ``+``/``-`` written right after ``prev`` and ending the statement."""
        tok = self.tok
        if (tok.kind in _ADD_OPS and tok.start == prev.end
                and self.toks[self.i + 1].kind in _SEPARATORS):
            return self.advance().kind
        return None

    def motor_suffix(self, prev: _Tok) -> int | None:
        """An optional ``.n`` written right after a command symbol."""
        tok = self.attached(prev, "mot")
        return None if tok is None else tok.motor

    def no_motor(self, tok: _Tok) -> None:
        if tok.motor is not None:
            self.fail("no motor ID allowed here", tok.mpos)

    def no_index(self, tok: _Tok) -> None:
        if tok.val is not None:
            self.fail(f"{tok.text} takes no number", tok.ipos)

    def index(self, tok: _Tok, what: str = "number", top: int = MAX_INDEX) -> int:
        """The required number of ``tok`` (a word's index or a num's value)."""
        if tok.val is None:
            self.fail(f"{tok.text or 'command'} needs a {what}", tok.end)
        if tok.val > top:
            self.fail(f"{what} must be 0..{top}", tok.ipos)
        return tok.val

    def opt_index(self, tok: _Tok) -> int | None:
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

    def branch(self, condition: Expr, first: _Tok) -> Branch:
        """``condition, then, else``; then/else are ``:``-joined (6.3 "I", "V")."""
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

    def register_statement(self, tok: _Tok, head: bool) -> Statement | Expr:
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
        self.unexpected(nxt)

    def word_statement(self, tok: _Tok) -> Statement:
        """Letter commands: Y Q Z O F C J CL JL X W B L END (2.2.2, 2.2.3)."""
        word = tok.text
        self.advance()
        if word in ("Y", "Q", "Z"):
            return Move(word, self.opt_index(tok), tok.motor, self.modifier(tok))  # type: ignore[arg-type]
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

    def loop(self, tok: _Tok) -> Loop | LoopEnd:
        """``X#.n`` loop count 0..255, ``X.n-`` end of loop (2.2.2 "X")."""
        if tok.val is None:
            if self.modifier(tok) != "-":
                self.fail("X needs a loop count, or '-' to end the loop", tok.end)
            return LoopEnd(tok.motor)
        return Loop(self.index(tok, "loop count", MAX_LOOP), tok.motor)

    def symbol_statement(self, tok: _Tok) -> Statement:
        """Execution commands and queries (2.1.2, 6.5, 6.6)."""
        kind = tok.kind
        method = _SYMBOL_METHODS.get(kind)
        if method is None:
            self.unexpected(tok)
        self.advance()
        if method == "simple":
            return Exec(_SIMPLE_EXEC[kind], self.motor_suffix(tok))  # type: ignore[arg-type]
        return getattr(self, method)(tok)

    def go(self, tok: _Tok) -> Exec:
        """``^.n``; ``^1`` as written in 2.2.3 is read as ``^.1``."""
        num = self.attached(tok, "num")
        if num is not None:
            self.no_motor(num)
            if not 1 <= num.val <= MAX_MOTOR:  # type: ignore[operator]
                self.fail(f"motor ID must be 1..{MAX_MOTOR}", num.start)
            return Exec("go", num.val)
        return Exec("go", self.motor_suffix(tok))

    def digit_exec(self, tok: _Tok, ops: dict[int, str], plain: str) -> Exec:
        """``|`` ``|1`` ``|2``, ``*`` ``*1``, ``]`` ``]1`` with optional ``.n``."""
        num = self.attached(tok, "num")
        if num is None:
            return Exec(plain, self.motor_suffix(tok))  # type: ignore[arg-type]
        if num.val not in ops:
            self.fail(f"{tok.kind}{num.val} is not a command", num.start)
        return Exec(ops[num.val], num.motor)  # type: ignore[arg-type,index]

    def origin(self, tok: _Tok) -> Exec:
        return self.digit_exec(tok, {1: "go_origin", 2: "set_origin"}, "origin")

    def estop(self, tok: _Tok) -> Exec:
        return self.digit_exec(tok, {1: "estop_release"}, "estop")

    def pause(self, tok: _Tok) -> Exec | StopBank:
        """``]`` ``]1.n`` pause, ``]L.n`` ``]LM.n`` stop a ladder bank (6.5)."""
        word = self.attached(tok, "word")
        if word is None:
            return self.digit_exec(tok, {1: "pause_motor"}, "pause")
        if word.text not in ("L", "LM"):
            self.unexpected(word)
        self.no_index(word)
        return StopBank(word.text, word.motor)  # type: ignore[arg-type]

    def start_bank(self, tok: _Tok) -> StartBank:
        """``[#.n``, ``[`` (resume), ``[L#.n``, ``[LM#.n`` (6.5, RT3 3.2)."""
        nxt = self.attached(tok, "num", "mot", "word")
        if nxt is None:
            return StartBank("B")
        if nxt.kind == "word" and nxt.text not in ("L", "LM"):
            self.unexpected(nxt)
        kind = nxt.text if nxt.kind == "word" else "B"
        return StartBank(kind, self.opt_index(nxt), nxt.motor)  # type: ignore[arg-type]

    def query(self, tok: _Tok) -> Query:
        """``?``, ``?.n``, ``?#.n``, ``?A.n`` ... ``?L#.n`` (6.6)."""
        nxt = self.attached(tok, "num", "mot", "word")
        if nxt is None:
            return Query()
        if nxt.kind == "word" and nxt.text not in _QUERY_LETTERS:
            self.fail(f"unknown query ?{self.text[nxt.start:nxt.ipos]}", nxt.start)
        letter = nxt.text if nxt.kind == "word" else None
        return Query(self.opt_index(nxt), letter, nxt.motor)

    def capture(self, tok: _Tok) -> Capture:
        """``#x.n``: capture the position into P memory x (2.1.2 "#")."""
        num = self.attached(tok, "num")
        if num is None:
            self.fail("# needs a P memory number", tok.end)
        return Capture(self.index(num, "P memory number"), num.motor)

    def interp(self, tok: _Tok) -> Interp:
        """``@#.n+`` / ``@.n-`` / ``@#.n`` (2.1.2 "@")."""
        nxt = self.attached(tok, "num", "mot") or tok
        if nxt is tok:
            return Interp(None, None, self.modifier(tok))  # type: ignore[arg-type]
        return Interp(self.opt_index(nxt), nxt.motor, self.modifier(nxt))  # type: ignore[arg-type]

    def alloc(self, tok: _Tok) -> Alloc:
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

    def operand_word(self, tok: _Tok) -> Expr:
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


_SYMBOL_METHODS: Final = {
    "^": "go", "|": "origin", "*": "estop", "]": "pause", "[": "start_bank",
    "?": "query", "#": "capture", "@": "interp", "\\": "alloc",
    "(": "simple", ")": "simple", "}": "simple", ">": "simple", "<": "simple",
    "$": "simple",
}
