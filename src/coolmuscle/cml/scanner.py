"""The CML scanner: one physical line -> tokens, for :mod:`coolmuscle.cml.parser`.

This module owns CML *lexing*: what a token is (a letter word with its memory
number and motor ID written without blanks, ``P2.1``; a number; ``.n``; a string;
an operator), where a comment starts (``//`` always; a single ``/`` unless it is a
division, cm-banks-rt3.txt 1.1 "/"), the digit limits, and two per-statement rules
that are cheapest to check on tokens: one Not operator per statement
(cml-users-guide.txt 6.8) and bounded size/nesting, so that no input can make the
parser recurse deeply.  Errors are :class:`~coolmuscle.errors.CmlSyntaxError`.
"""

from __future__ import annotations

import re
from typing import Final, NoReturn

from coolmuscle.errors import CmlSyntaxError

__all__ = ["Tok", "scan", "fail", "MAX_NUMBER_DIGITS", "MAX_INDEX", "MAX_MOTOR",
           "MAX_LOOP", "MAX_STATEMENT_TOKENS", "MAX_NESTING"]

#: Longest digit run accepted anywhere (data range is +-1,000,000,000).
MAX_NUMBER_DIGITS: Final = 10
#: Largest memory / bank / output / query number (``?1000`` is the largest used).
MAX_INDEX: Final = 9999
#: Motor IDs the parser accepts after the dot (the executor checks 1..15).
MAX_MOTOR: Final = 99
#: Largest loop count ``X#`` (cml-users-guide.txt 2.2.2 "X": 0 ~ 255).
MAX_LOOP: Final = 255
#: Most tokens in one statement (between ``, : ;``); the motor itself takes 40
#: characters between commas (cm-banks-rt3.txt 3.3.2).  Bounds tree depth.
MAX_STATEMENT_TOKENS: Final = 128
#: Deepest ``U#(`` / ``!!(`` nesting; bounds the recursion of the parser.
MAX_NESTING: Final = 16

# One token per match; leading blanks are skipped.  Groups, in order: a word with
# its letters, index and motor; a number with its digits and motor; a ".n" motor
# suffix and its digits; a string and its body; an operator.
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
# What can start an operand (the FIRST set of parser._Parser.primary): a single "/"
# followed by one of these is a division, otherwise it starts a comment.
_OPERAND_START_RE: Final = re.compile(
    r"[ \t]*(?:[0-9\"!]|[-+][0-9]|[PSAMTVNRKHpsamtvnrkh](?![A-Za-z])|[IiUu][0-9])"
)

_OPERAND_END: Final = frozenset({"word", "num", "str", ")"})
_NOT_OPS: Final = frozenset({"!", "!!"})
_BACKSLASHES: Final = {"\\": "\\", "\u00a5": "\\", "\u20a9": "\\"}  # \, yen, won


class Tok:
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


def fail(text: str, message: str, position: int) -> NoReturn:
    raise CmlSyntaxError(message, text=text, position=position)


def _number(text: str, digits: str | None, pos: int) -> int | None:
    """Digits -> int, refusing runs longer than :data:`MAX_NUMBER_DIGITS`."""
    if digits is None:
        return None
    if len(digits) > MAX_NUMBER_DIGITS:
        fail(text, f"number longer than {MAX_NUMBER_DIGITS} digits", pos)
    return int(digits)


def _motor(text: str, digits: str | None, dot: int) -> int | None:
    """The motor ID after a dot: 1..99 (cml-users-guide.txt 2.1 ".n")."""
    value = _number(text, digits, dot + 1)
    if value is not None and not 1 <= value <= MAX_MOTOR:
        fail(text, f"motor ID must be 1..{MAX_MOTOR}", dot + 1)
    return value


def _bad_character(text: str, pos: int) -> NoReturn:
    char = text[pos]
    if char == '"':
        close = text.find('"', pos + 1)
        if close < 0:
            fail(text, "unterminated string", pos)
        bad = next((i for i in range(pos + 1, close) if not " " <= text[i] <= "~"), pos)
        fail(text, f"invalid character {text[bad]!r} in string", bad)
    if char == ".":
        fail(text, "'.' must be followed by a motor ID", pos)
    fail(text, f"invalid character {char!r}", pos)


def scan(text: str) -> tuple[list[Tok], int]:
    """Tokens of ``text`` up to its comment, ending with an "eof" token.

    Returns the tokens and the column where the code ends (comment start or
    length).  ``//`` always starts a comment; a single ``/`` is a division only
    after an operand and before something that can start one (RT3 1.1 "/").
    """
    toks: list[Tok] = []
    append = toks.append
    match = _TOKEN_RE.match
    pos, size, last = 0, len(text), ""
    nots = depth = count = 0  # per statement: Not operators, open "(", tokens
    while pos < size:
        m = match(text, pos)
        if m is None:
            blanks = _BLANKS_RE.match(text, pos)      # matches: it may match nothing
            pos = blanks.end() if blanks else pos
            if pos < size:
                _bad_character(text, pos)
            break
        pos = m.end()
        word, letters, index, wmotor, num, digits, nmotor, mot, mdigits, _, body, op = \
            m.groups()
        if letters is not None:
            start = pos - len(word)
            ipos = start + len(letters)
            dot = ipos + len(index) if index else ipos
            tok = Tok("word", start, pos, letters.upper(),
                      None if index is None else _number(text, index, ipos),
                      None if wmotor is None else _motor(text, wmotor, dot), ipos, dot)
        elif digits is not None:
            start = pos - len(num)
            dot = start + len(digits)
            tok = Tok("num", start, pos, "", _number(text, digits, start),
                      None if nmotor is None else _motor(text, nmotor, dot), start, dot)
        elif mdigits is not None:
            start = pos - len(mot)
            tok = Tok("mot", start, pos, "", None, _motor(text, mdigits, start),
                      start, start)
        elif body is not None:
            start = pos - len(body) - 2
            tok = Tok("str", start, pos, body)
        else:
            start = pos - len(op)
            op = _BACKSLASHES.get(op, op)
            if op == "//" or (op == "/" and not (
                    last in _OPERAND_END and _OPERAND_START_RE.match(text, pos))):
                return _finish(toks, start)
            if op in _NOT_OPS:
                nots += 1
                if nots > 1:
                    fail(text, "only one Not operator is allowed in a statement", start)
            elif op == "(":
                depth += 1
                if depth > MAX_NESTING:
                    fail(text, f"more than {MAX_NESTING} nested parentheses", start)
            elif op == ")":
                depth = max(depth - 1, 0)
            elif op in (",", ":", ";"):
                nots = depth = count = 0
            tok = Tok(op, start, pos)
        count += 1
        if count > MAX_STATEMENT_TOKENS:
            fail(text, f"statement longer than {MAX_STATEMENT_TOKENS} tokens", start)
        append(tok)
        last = tok.kind
    return _finish(toks, size)


def _finish(toks: list[Tok], code_end: int) -> tuple[list[Tok], int]:
    end = toks[-1].end if toks else 0
    toks.append(Tok("eof", end, end))
    return toks, code_end
