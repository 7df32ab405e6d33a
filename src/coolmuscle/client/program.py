"""A ``.cml`` file as the motor will receive it: direct lines and bank definitions.

Shared by the uploader (:meth:`coolmuscle.client.CoolMuscle.upload`, ``coolmuscle
upload``, ``:send`` in ``coolmuscle term``) and the linter (``coolmuscle check``).
It owns how a file is cut into what is sent:

* a bank definition starts with ``B#.n`` / ``L#.n`` alone on its line and ends with
  ``END`` (cml-users-guide.txt 2.2.2, 2.2.3) or with an empty line ("Program Bank is
  terminated also with the linefeed and without any command");
* everything else is a direct-mode line, sent and executed at once (2.1);
* comments (``//``, RT3's ``/``) are not sent; a comment-only line is skipped and does
  not end a bank;
* the script format of ``coolmuscle run`` (docs/scripts.md) is understood, so that the
  same file can be run, checked and uploaded: ``# comment`` lines, ``@`` directives and
  ``<<`` expectations are not CML and are skipped.  A comment line
  ``# coolmuscle: firmware=rt3 motors=2`` names the firmware profile and chain size
  the file is written for.

Every line is parsed with the one parser (:func:`coolmuscle.cml.parse`).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final, Literal

from ..cml import ast
from ..cml.formatter import format_line
from ..cml.parser import parse
from ..errors import CmlSyntaxError, InvalidArgumentError

__all__ = ["SourceLine", "BankBlock", "ProgramFile", "parse_program", "load_program",
           "canonical_lines"]

_DIRECTIVE_RE: Final = re.compile(r"@[A-Za-z]")
_MAGIC_RE: Final = re.compile(r"#\s*coolmuscle:\s*(.*)")
_OPTION_RE: Final = re.compile(r"(firmware|motors)=(\S+)")

ClosedBy = Literal["END", "blank", "eof"]


@dataclass
class SourceLine:
    """One physical line of the file that holds CML.

    ``lines`` is what the parser made of it (``[]`` for a comment-only line);
    ``error`` is set instead when it does not parse.  ``send`` is the text sent to
    the motor: the statements without the comment.
    """

    number: int
    raw: str
    lines: list[ast.Line] = field(default_factory=list)
    error: CmlSyntaxError | None = None

    @property
    def send(self) -> str:
        if self.error is not None or not self.lines:
            return self.raw.strip()
        return " ".join(line.source + (";" if line.joined else "") for line in self.lines)

    @property
    def statements(self) -> Iterator[ast.Statement]:
        for line in self.lines:
            yield from line.statements

    @property
    def blank(self) -> bool:
        return not self.raw.strip()


@dataclass
class BankBlock:
    """A bank definition: header line, body lines, and how it ended."""

    ladder: bool
    number: int
    motor: int | None
    header: SourceLine
    body: list[SourceLine] = field(default_factory=list)
    end: SourceLine | None = None
    closed_by: ClosedBy = "eof"

    @property
    def label(self) -> str:
        """``B1.1`` / ``L2.1`` as it would be written (motor 1 when none is given)."""
        return f"{'L' if self.ladder else 'B'}{self.number}.{self.motor_id}"

    @property
    def motor_id(self) -> int:
        return self.motor or 1

    @property
    def kind(self) -> str:
        return "ladder" if self.ladder else "program"

    def send_lines(self) -> list[str]:
        """What is sent: the header, every body line that holds CML, and the end."""
        out = [self.header.send]
        out += [line.send for line in self.body if line.lines or line.error]
        if self.closed_by == "END" and self.end is not None:
            out.append(self.end.send)
        elif self.closed_by == "blank":
            out.append("")
        return out


Item = SourceLine | BankBlock


@dataclass
class ProgramFile:
    """A parsed file: items in order, plus what its magic comment says."""

    items: list[Item]
    path: str = "<text>"
    firmware: str | None = None
    motors: int | None = None

    @property
    def banks(self) -> list[BankBlock]:
        return [item for item in self.items if isinstance(item, BankBlock)]

    @property
    def source_lines(self) -> Iterator[SourceLine]:
        """Every CML line in file order, bank headers, bodies and ends included."""
        for item in self.items:
            if isinstance(item, BankBlock):
                yield item.header
                yield from item.body
                if item.end is not None:
                    yield item.end
            else:
                yield item

    def send_count(self) -> int:
        """How many lines an upload sends (for progress bars)."""
        count = 0
        for item in self.items:
            count += len(item.send_lines()) if isinstance(item, BankBlock) else 1
        return count


def _bank_header(line: SourceLine) -> ast.BankBegin | None:
    statements = list(line.statements)
    if statements and isinstance(statements[0], ast.BankBegin):
        return statements[0]
    return None


def _is_end(line: SourceLine) -> bool:
    statements = list(line.statements)
    return len(statements) == 1 and isinstance(statements[0], ast.BankEnd)


def _not_cml(raw: str) -> bool:
    """Script-format lines (docs/scripts.md) that are not sent as CML."""
    stripped = raw.lstrip()
    if stripped == "#" or stripped.startswith("# ") or stripped.startswith("#\t"):
        return True
    return bool(_DIRECTIVE_RE.match(stripped)) or stripped.startswith("<< ")


def _magic(raw: str, program: ProgramFile) -> None:
    match = _MAGIC_RE.match(raw.strip())
    if match is None:
        return
    for key, value in _OPTION_RE.findall(match.group(1)):
        if key == "firmware":
            program.firmware = value.lower()
        elif value.isdigit():
            program.motors = int(value)


def _source_line(number: int, raw: str) -> SourceLine:
    try:
        return SourceLine(number, raw, parse(raw))
    except CmlSyntaxError as error:
        return SourceLine(number, raw, error=error)


def parse_program(text: str, path: str = "<text>") -> ProgramFile:
    """Cut ``text`` into direct lines and bank blocks (see the module docstring)."""
    program = ProgramFile([], path)
    bank: BankBlock | None = None
    for number, raw in enumerate(text.splitlines(), start=1):
        if _not_cml(raw):
            _magic(raw, program)
            continue
        line = _source_line(number, raw)
        if bank is not None:
            if line.blank:
                bank.end, bank.closed_by, bank = line, "blank", None
            elif _is_end(line):
                bank.end, bank.closed_by, bank = line, "END", None
            else:
                bank.body.append(line)
            continue
        if line.blank or (not line.lines and line.error is None):
            continue
        header = _bank_header(line)
        if header is not None:
            bank = BankBlock(header.ladder, header.index, header.motor, line)
            program.items.append(bank)
        else:
            program.items.append(line)
    return program


def load_program(path: str | Path) -> ProgramFile:
    """Read and parse a ``.cml`` file (UTF-8; the yen sign reads as ``\\``)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise InvalidArgumentError(f"{path}: not UTF-8 text (byte {exc.start}); a .cml "
                                   "file is text") from None
    except IsADirectoryError:
        raise InvalidArgumentError(f"{path} is a directory, not a .cml file") from None
    return parse_program(text, str(path))


def _fill_reg(reg: ast.Reg, motor: int) -> ast.Reg:
    return reg if reg.motor is not None else dataclasses.replace(reg, motor=motor)


def _fill_expr(expr: ast.Expr, motor: int) -> ast.Expr:
    if isinstance(expr, ast.Reg):
        return _fill_reg(expr, motor)
    if isinstance(expr, ast.Input):
        return expr if expr.motor is not None else dataclasses.replace(expr, motor=motor)
    if isinstance(expr, (ast.BinOp, ast.Compare, ast.Logic)):
        return dataclasses.replace(expr, left=_fill_expr(expr.left, motor),
                                   right=_fill_expr(expr.right, motor))
    if isinstance(expr, ast.Func):
        return dataclasses.replace(expr, arg=_fill_expr(expr.arg, motor))
    if isinstance(expr, ast.Not):
        return dataclasses.replace(expr, operand=_fill_expr(expr.operand, motor))
    return expr


def _fill(statement: ast.Statement, motor: int) -> ast.Statement:
    """``statement`` with the bank's motor ID where it names none (``S1`` in ``B1.2``)."""
    if isinstance(statement, ast.Assign):
        return dataclasses.replace(statement, target=_fill_reg(statement.target, motor),
                                   value=_fill_expr(statement.value, motor))
    if isinstance(statement, ast.Ref):
        return dataclasses.replace(statement, reg=_fill_reg(statement.reg, motor))
    if isinstance(statement, ast.Branch):
        return ast.Branch(_fill_expr(statement.condition, motor),
                          tuple(_fill(s, motor) for s in statement.then),
                          tuple(_fill(s, motor) for s in statement.orelse))
    if isinstance(statement, ast.OutputWord):
        statement = dataclasses.replace(statement, value=_fill_expr(statement.value, motor))
    if isinstance(statement, ast.Alloc) or getattr(statement, "motor", 0) is not None:
        return statement
    return dataclasses.replace(statement, motor=motor)


def canonical_lines(texts: list[str], motor: int | None = None) -> list[str]:
    """Canonical logical lines (6.6 readback form) of bank text, for comparison.

    Each text is parsed and every logical line printed by the formatter, with
    ``motor`` written where a statement names no motor ID (a motor stores ``S1`` of
    ``B1.2`` as ``S1.2``); bank headers and ``END`` are dropped, so a listing that
    prints them and one that does not compare equal.  A text that does not parse is
    kept as written (stripped).
    """
    out: list[str] = []
    for text in texts:
        try:
            lines = parse(text)
        except CmlSyntaxError:
            out.append(text.strip())
            continue
        for line in lines:
            if any(isinstance(s, (ast.BankBegin, ast.BankEnd)) for s in line.statements):
                continue
            if motor is not None:
                line = dataclasses.replace(
                    line, statements=tuple(_fill(s, motor) for s in line.statements))
            out.append(format_line(line))
    return out
