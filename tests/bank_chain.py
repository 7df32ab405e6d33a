"""A chain that stores bank definitions and lists them as cml-users-guide.txt 6.6 shows.

Program and ladder banks belong to another branch of the project; until they are on
main, this stand-in gives the uploader something to verify against: ``B#.n``/``L#.n``
opens a definition, ``END`` or an empty line closes it (2.2.2), the lines are kept in
canonical form, ``?#.n`` / ``?L#.n`` list them ("Only the predefined content after
B#.n"), a line that does not parse answers ``error01.n`` (K23 16).  ``corrupt`` maps a
``(bank, line index)`` to the text stored instead, like a motor that "won't load the
bank correctly" (cm-banks-rt3.txt 3.3.2).  Everything else is the real chain.
"""

from __future__ import annotations

from typing import Any

from coolmuscle.chain import Chain
from coolmuscle.cml import ast
from coolmuscle.cml.formatter import format_line
from coolmuscle.cml.parser import parse
from coolmuscle.errors import CmlSyntaxError
from coolmuscle.motor.motor import Motor

BankKey = tuple[bool, int, int]


class BankChain(Chain):
    """The real chain plus bank definition storage and listing (see module docstring)."""

    corrupt: dict[tuple[str, int], str] = {}

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.banks: dict[BankKey, list[str]] = {}
        self._defining: BankKey | None = None
        super().__init__(*args, **kwargs)

    def _on_host_line(self, text: str) -> None:
        if self._defining is not None:
            self._definition_line(text)
            return
        try:
            lines = parse(text)
        except CmlSyntaxError:
            lines = []
        first = lines[0].statements[0] if lines and lines[0].statements else None
        if isinstance(first, ast.BankBegin):
            self._defining = (first.ladder, first.index, first.motor or 1)
            self.banks[self._defining] = []
            return
        super()._on_host_line(text)

    def _definition_line(self, text: str) -> None:
        assert self._defining is not None
        motor = self.motors[self._defining[2]]
        try:
            lines = parse(text)
        except CmlSyntaxError as error:
            motor.report_error(None, error)
            return
        if not text.strip() or any(isinstance(s, ast.BankEnd)
                                   for line in lines for s in line.statements):
            self._defining = None
            return
        stored = self.banks[self._defining]
        label = f"{'L' if self._defining[0] else 'B'}{self._defining[1]}.{self._defining[2]}"
        for line in lines:
            stored.append(self.corrupt.get((label, len(stored)), format_line(line)))

    def bank_query(self, motor: Motor, query: ast.Query) -> list[str] | None:
        if query.number == 1000 and query.letter is None:   # as the bank model prints it
            out: list[str] = []
            for (ladder, number, owner), lines in sorted(self.banks.items()):
                if owner == motor.id:
                    out += [f"{'L' if ladder else 'B'}{number}.{owner}", *lines,
                            f"END.{owner}"]
            return out + [f"Steps.{motor.id}: program 0, ladder 0, total 0/500"]
        key = (query.letter == "L", query.number or 0, motor.id)
        return list(self.banks.get(key, [])) if query.number else None
