"""Bank upload, readback and verification (sans-IO operations).

Upload (cml-users-guide.txt 2.2.2, 2.2.3; cm-banks-rt3.txt 3.3): a file is sent line
by line as a terminal program would.  Direct lines are executed at once and fenced
(:func:`coolmuscle.client.ops.fenced`), so their errors are known.  Inside a bank
definition nothing else may be sent (a query would become part of the bank), so each
line waits for its echo when the motor echoes, or for ``line_delay`` seconds when it
does not ("COOL MUSCLE's communication buffer could be overflowed", ch. 3 K20).

Verification: "It is good practice to query the banks (?1000) after it has been sent"
(RT3 3.3.2).  Each uploaded bank is read back with ``?#.n`` / ``?L#.n`` (6.6) and
compared line by line in canonical form (:func:`coolmuscle.client.program.canonical_lines`):
what the file says and what the motor holds, parsed and printed by the one formatter.
``?1000.n`` lists every bank at once (:func:`all_banks`).
"""

from __future__ import annotations

import dataclasses
import difflib
import re
from collections.abc import Callable
from dataclasses import dataclass, field

from ..cml import ast
from ..cml.parser import parse
from ..errors import CmlSyntaxError, CoolMuscleError, MotorError
from . import args
from .ops import Op, Pause, Session, exchange, fenced, listing
from .program import BankBlock, ProgramFile, SourceLine, canonical_lines
from .protocol import Exchange

__all__ = ["BankDifference", "UploadResult", "UploadError", "upload", "read_bank",
           "all_banks", "parse_bank_listing", "compare_bank", "send_line", "save",
           "Progress"]

#: ``progress(lines_sent, lines_total)``.
Progress = Callable[[int, int], None]

#: Seconds between bank lines when the motor does not echo.
DEFAULT_LINE_DELAY = 0.02


@dataclass(frozen=True)
class BankDifference:
    """One place where a bank read back differs from the file."""

    bank: str                 # "B1.1" / "L2.1"
    line: int                 # 1-based line of the bank body (as read back)
    expected: str | None      # canonical text from the file (None: extra line)
    got: str | None           # canonical text from the motor (None: missing line)
    source_line: int | None = None  # line number in the file

    def format(self) -> str:
        where = f"{self.bank} line {self.line}"
        if self.source_line is not None:
            where += f" (file line {self.source_line})"
        if self.got is None:
            return f"{where}: missing on the motor: {self.expected!r}"
        if self.expected is None:
            return f"{where}: extra on the motor: {self.got!r}"
        return f"{where}: expected {self.expected!r}, motor has {self.got!r}"


@dataclass
class UploadResult:
    """What an upload did: lines sent, errors the motor reported, readback differences."""

    sent: int = 0
    banks: list[str] = field(default_factory=list)
    errors: list[tuple[int, MotorError]] = field(default_factory=list)   # (file line, error)
    differences: list[BankDifference] = field(default_factory=list)
    verified: bool = False
    saved: list[int] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.errors and not self.differences

    def report(self) -> list[str]:
        """Human-readable lines: each error and each difference."""
        out = [f"line {line}: {error}" for line, error in self.errors]
        out += [d.format() for d in self.differences]
        return out


def read_bank(session: Session, motor: int, number: int, ladder: bool = False,
              timeout: float | None = None) -> Op[list[str]]:
    """``?#.n`` / ``?L#.n``: the bank's lines as the motor prints them (6.6)."""
    from .commands import bank_number  # noqa: PLC0415  (commands imports this module's kin)
    number = yield from bank_number(session, motor, number, ladder)
    text = f"?{'L' if ladder else ''}{number}.{motor}"
    lines = yield from listing(session, motor, text, timeout=timeout)
    return lines


def all_banks(session: Session, motor: int,
              timeout: float | None = None) -> Op[dict[str, list[str]]]:
    """``?1000.n``: every program and ladder bank, ``{"B1.1": [lines], "L2.1": [...]}``
    (6.6; RT3 2.3 also prints step counts, which are left out)."""
    lines = yield from listing(session, motor, f"?1000.{motor}", timeout=timeout)
    return parse_bank_listing(lines)


_HEADER = re.compile(r"([BL])(\d+)(?:\.(\d+))?", re.IGNORECASE)
_END = re.compile(r"END(?:\.\d+)?", re.IGNORECASE)


def parse_bank_listing(lines: list[str], motor: int = 1) -> dict[str, list[str]]:
    """Split a ``?1000`` listing into banks: a ``B#.n``/``L#.n`` line opens one, ``END``
    closes it; lines outside a bank (a step count summary) are not part of any."""
    banks: dict[str, list[str]] = {}
    current: list[str] | None = None
    for line in lines:
        text = line.strip()
        header = _HEADER.fullmatch(text)
        if header:
            label = f"{header.group(1).upper()}{header.group(2)}.{header.group(3) or motor}"
            current = banks.setdefault(label, [])
        elif _END.fullmatch(text):
            current = None
        elif current is not None:
            current.append(text)
    return banks


def compare_bank(block: BankBlock, got: list[str]) -> list[BankDifference]:
    """Differences between a block of the file and the lines the motor printed."""
    sources = [line for line in block.body if line.lines or line.error is not None]
    expected: list[str] = []
    origin: list[int] = []
    for line in sources:
        canon = canonical_lines([line.send], block.motor_id)
        expected += canon
        origin += [line.number] * len(canon)
    actual = canonical_lines(got, block.motor_id)
    diffs: list[BankDifference] = []
    matcher = difflib.SequenceMatcher(a=expected, b=actual, autojunk=False)
    for op, a0, a1, b0, b1 in matcher.get_opcodes():
        if op == "equal":
            continue
        for k in range(max(a1 - a0, b1 - b0)):
            exp = expected[a0 + k] if a0 + k < a1 else None
            act = actual[b0 + k] if b0 + k < b1 else None
            src = origin[a0 + k] if a0 + k < a1 else None
            diffs.append(BankDifference(block.label, (b0 if act is not None else a0) + k + 1,
                                        exp, act, src))
    return diffs


def _send_direct(session: Session, line: SourceLine, result: UploadResult,
                 default: int) -> Op[None]:
    motor = _motor_of(line, default)
    try:
        yield from fenced(session, motor, (line.send,))
    except MotorError as error:
        result.errors.append((line.number, error))


def _motor_of(line: SourceLine, default: int = 1) -> int:
    for statement in line.statements:
        motor = getattr(statement, "motor", None)
        if motor is None and hasattr(statement, "target"):
            motor = statement.target.motor
        if motor is None and hasattr(statement, "reg"):
            motor = statement.reg.motor
        if motor is not None:
            return int(motor)
    return default


def _send_bank(session: Session, block: BankBlock, line_delay: float,
               result: UploadResult, tick: Callable[[], None]) -> Op[None]:
    """Header, body and end, each line paced by its echo (or ``line_delay``)."""
    motor = block.motor_id
    protocol = session.protocol
    numbers = [block.header.number]
    numbers += [line.number for line in block.body if line.lines or line.error]
    numbers.append(block.end.number if block.end is not None else block.header.number)
    marks: list[tuple[int, int]] = []   # (seq of the line's echo, or when sent; file line)
    for text, number in zip(block.send_lines(), numbers):
        if protocol.echo and text:
            ex = yield Exchange((text,), _never, motor, "echo", timeout=session.timeout,
                                until_echo=True)
            marks.append((ex.end_seq, number))
        else:
            marks.append((protocol.seq, number))
            yield _raw(text)
            yield Pause(line_delay)
        tick()
    lines = yield from fenced(session, motor, ())
    for event in protocol.events_since(marks[0][0]):
        if event.kind == "error" and event.motor == motor:
            number = max(((seq, n) for seq, n in marks if seq < event.seq),
                         default=(0, numbers[0]))[1]
            result.errors.append((number, _error_of(event.text)))
    for line in lines:
        if line.kind == "error":
            result.errors.append((numbers[-1], line.error()))
    result.banks.append(block.label)


def _never(_line: object) -> bool:
    return False


def _raw(text: str) -> Exchange:
    """Write a line with nothing to wait for (an exchange that is complete at once)."""
    ex = Exchange((text,), lambda _l: True, None, "nothing", timeout=0.0)
    ex.complete = True
    return ex


def _error_of(text: str) -> MotorError:
    from .replies import classify
    return classify(text.encode("latin-1")).error()


def upload(session: Session, program: ProgramFile, *, verify: bool = True,
           line_delay: float = DEFAULT_LINE_DELAY, progress: Progress | None = None,
           motor: int = 1) -> Op[UploadResult]:
    """Send ``program``; then read every bank back and compare (module docstring).

    ``motor``: the ID the lines without ``.n`` address (ID1 on a host line; a
    driver whose line takes another default, such as the web page's, says so)."""
    result = UploadResult()
    program = _addressed(program, motor)
    total = program.send_count()
    if session.protocol.echo is None and program.items:
        first = program.items[0]
        fence = first.motor_id if isinstance(first, BankBlock) else _motor_of(first, motor)
        yield from fenced(session, fence, ())   # learn whether the motor echoes

    def tick() -> None:
        result.sent += 1
        if progress is not None:
            progress(result.sent, total)

    for item in program.items:
        if isinstance(item, BankBlock):
            yield from _send_bank(session, item, line_delay, result, tick)
        else:
            yield from _send_direct(session, item, result, motor)
            tick()
    if verify:
        for block in program.banks:
            try:
                got = yield from read_bank(session, block.motor_id, block.number, block.ladder)
            except MotorError as error:
                result.errors.append((block.header.number, error))
                continue
            result.differences += compare_bank(block, got)
        result.verified = True
    return result


def _addressed(program: ProgramFile, motor: int) -> ProgramFile:
    """``program`` with its bank headers without ``.n`` given ``motor`` (a copy)."""
    if all(block.motor is not None for block in program.banks):
        return program
    items: list[BankBlock | SourceLine] = [
        dataclasses.replace(item, motor=motor)
        if isinstance(item, BankBlock) and item.motor is None else item
        for item in program.items]
    return dataclasses.replace(program, items=items)


def save(session: Session, motor: int, timeout: float = 5.0) -> Op[None]:
    """``$.n``; waits for ``saved.n`` (2.1.2)."""
    timeout = args.seconds("timeout", timeout)  # type: ignore[assignment]
    wanted = f"saved.{motor}"
    yield from exchange(session, (f"$.{motor}",), lambda l: l.text == wanted, motor,
                        f"'{wanted}'", timeout)


class UploadError(CoolMuscleError):
    """An upload the motor reported errors for, or whose readback differs."""

    def __init__(self, result: UploadResult) -> None:
        self.result = result
        lines = result.report()
        super().__init__(f"upload failed: {len(lines)} problem(s): " + "; ".join(lines[:3]))


def _bank_edge(line: str) -> str | None:
    """``"begin"`` for a ``B#``/``L#`` line, ``"end"`` for ``END`` or an empty line."""
    if not line.strip():
        return "end"
    try:
        statements = [s for l in parse(line) for s in l.statements]
    except CmlSyntaxError:
        return None
    if any(isinstance(s, ast.BankBegin) for s in statements):
        return "begin"
    if any(isinstance(s, ast.BankEnd) for s in statements):
        return "end"
    return None


def send_line(session: Session, motor: int, line: str,
              timeout: float | None = None) -> Op[list[str]]:
    """Send one line as typed; return what the motor answered to it.

    Outside a bank definition the line is fenced (its replies and errors are complete
    on return).  A ``B#``/``L#`` line opens a definition: until ``END`` or an empty
    line, lines are sent alone and paced by their echo, since anything else sent
    would become part of the bank (2.2.2).
    """
    line = args.line(line)
    timeout = args.seconds("timeout", timeout, allow_none=True)
    edge = _bank_edge(line)
    if session.defining or edge == "begin":
        session.defining = edge != "end"
        if session.protocol.echo and line:
            yield Exchange((line,), _never, motor, "echo", timeout=session.timeout
                           if timeout is None else timeout, until_echo=True)
        else:
            yield _raw(line)
            yield Pause(DEFAULT_LINE_DELAY)
        return []
    answer = yield from fenced(session, motor, (line,), timeout=timeout)
    return [reply.text for reply in answer[:-1]]
