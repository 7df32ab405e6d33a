"""Program and ladder banks: storage, upload from the host line, readback, saving.

A motor holds 30 program banks and 30 ladder banks (cml-users-guide.txt 2.2.2 "B 1 ~ 30",
2.2.3 "L 1 ~ 30").  A bank is defined by typing ``B#.n`` / ``L#.n`` on the host line;
the lines that follow are stored, not executed, until ``END`` (or ``END.n``) or a blank
line (2.2.2 "terminated also with the linefeed and without any command").  Each line is
stored with the bank's motor ID filled in where it names none, after the checks of
:mod:`.bankcheck`.  Loading stops at the first bad line (RT3 3.3 "the bank will cease
to load from that point on"): the lines before it stay, the rest up to ``END`` is
swallowed.  With K23 including 16 a good definition ends with ``[End of Bank]`` and a
bad line gives its ``errorNN.n`` (ch. 3 K23).

Readback: ``?#.n`` and ``?L#.n`` print one canonical line per stored line (6.6 "S1.1,
A1.1, P1.1"), ``?1000.n`` every bank with its header and ``END`` and the memory used.
Banks are part of the ``$`` snapshot as canonical text (docs/fidelity.md).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ...cml import ast
from ...cml.formatter import format_line
from ...cml.parser import parse
from ...cml.scanner import scan
from ...errors import CmlSyntaxError, MotorError, OutOfRangeError, TooManyStepsError
from ..state.firmware import Firmware
from ..status import Report
from .bankcheck import bank_header_cost, check_line, fill_motor, line_cost, memory_limit

if TYPE_CHECKING:
    from ..context import Context
    from ..core import MotorCore

log = logging.getLogger(__name__)

END_OF_BANK = "[End of Bank]"
Bank = list[ast.Line]


def condition_only(line: ast.Line) -> bool:
    """A branch condition without actions, joined to the next line (2.2.3 ";" example)."""
    stmt = line.statements[0] if len(line.statements) == 1 else None
    return (isinstance(stmt, ast.Branch) and not stmt.then and not stmt.orelse
            and line.joined)


class BankStore:
    """The banks of one motor and the memory they use (steps on RT3, commands on CM2)."""

    def __init__(self, firmware: Firmware) -> None:
        self.firmware = firmware
        self.program: dict[int, Bank] = {}
        self.ladder: dict[int, Bank] = {}
        self.version = 0  # bumped on every change (executors cache per version)

    def table(self, ladder: bool) -> dict[int, Bank]:
        return self.ladder if ladder else self.program

    def count(self, ladder: bool) -> int:
        """Banks of each kind (2.2.2, 2.2.3: 1 ~ 30)."""
        return self.firmware.ladder_banks if ladder else self.firmware.program_banks

    def get(self, ladder: bool, number: int) -> Bank | None:
        """The lines of a bank, or ``None`` when it was never defined."""
        return self.table(ladder).get(number)

    # -- memory -------------------------------------------------------------
    def bank_cost(self, bank: Bank) -> int:
        return bank_header_cost(self.firmware) + sum(line_cost(l, self.firmware) for l in bank)

    def used(self, ladder: bool | None = None) -> int:
        kinds = (False, True) if ladder is None else (ladder,)
        return sum(self.bank_cost(b) for k in kinds for b in self.table(k).values())

    @property
    def limit(self) -> int:
        return memory_limit(self.firmware)

    # -- changes --------------------------------------------------------------
    def begin(self, ladder: bool, number: int) -> None:
        """Start (re)defining a bank: its old lines are gone (error02 if no room)."""
        self.table(ladder).pop(number, None)
        self.version += 1
        if self.used() + bank_header_cost(self.firmware) > self.limit:
            raise TooManyStepsError()
        self.table(ladder)[number] = []

    def append(self, ladder: bool, number: int, lines: list[ast.Line]) -> None:
        """Store checked lines at the end of a bank (error02 beyond the limit)."""
        cost = sum(line_cost(l, self.firmware) for l in lines)
        if self.used() + cost > self.limit:
            raise TooManyStepsError()
        self.table(ladder)[number].extend(lines)
        self.version += 1

    def clear(self, ladder: bool) -> None:
        """``B100`` / ``L100`` (RT3 2.3, 3.2)."""
        self.table(ladder).clear()
        self.version += 1

    # -- readback -------------------------------------------------------------
    def listing(self, ladder: bool, number: int) -> list[str] | None:
        """``?#.n`` / ``?L#.n``: the stored lines, canonical, one reply line each."""
        bank = self.get(ladder, number)
        return None if bank is None else [format_line(line) for line in bank]

    def all_listing(self, motor_id: int) -> list[str]:
        """``?1000.n``: every bank with header and END, then the memory used (RT3 2.3)."""
        out: list[str] = []
        for ladder, letter in ((False, "B"), (True, "L")):
            for number in sorted(self.table(ladder)):
                out.append(f"{letter}{number}.{motor_id}")
                out += self.listing(ladder, number) or []
                out.append(f"END.{motor_id}")
        word = "Steps" if self.firmware.max_bank_steps is not None else "Commands"
        out.append(f"{word}.{motor_id}: program {self.used(False)}, ladder "
                   f"{self.used(True)}, total {self.used()}/{self.limit}")
        return out

    # -- saving -----------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON form for the ``$`` snapshot: canonical text lines per bank."""
        return {kind: {str(n): [format_line(l) for l in bank]
                       for n, bank in sorted(self.table(kind == "ladder").items())}
                for kind in ("program", "ladder")}

    def load_dict(self, data: Mapping[str, Any]) -> None:
        """Restore saved banks; a bank whose text no longer parses is skipped."""
        for kind in ("program", "ladder"):
            table = self.table(kind == "ladder")
            table.clear()
            for number, texts in dict(data.get(kind) or {}).items():
                try:
                    table[int(number)] = [l for text in texts for l in parse(str(text))]
                except (CmlSyntaxError, ValueError, TypeError) as exc:
                    log.warning("saved %s bank %s skipped: %s", kind, number, exc)
        self.version += 1


@dataclass
class _Session:
    """One bank definition in progress (on one origin: host line, API ...)."""

    motor: MotorCore | None
    ladder: bool
    number: int
    failed: bool = False
    pending_condition: bool = False


class BankUploads:
    """Bank definitions typed line by line, one session per sender (chain-level).

    A sender is the origin and its session (``Context.session``: one TCP client,
    the pty program, the Modbus CML input): an upload belongs to the sender that
    opened it, takes only that sender's lines, and ends when it goes away
    (:meth:`abandon`).
    """

    def __init__(self, motors: Mapping[int, MotorCore]) -> None:
        self.motors = motors
        self._sessions: dict[tuple[str, object], _Session] = {}

    def active(self, origin: str, session: object = None) -> bool:
        return (origin, session) in self._sessions

    def abandon(self, origin: str, session: object = None) -> bool:
        """The sender went away: its definition ends with the lines stored so far."""
        found = self._sessions.pop((origin, session), None)
        if found is not None:
            log.info("bank upload of a departed %s sender ended", origin)
        return found is not None

    def begins(self, lines: list[ast.Line], ctx: Context) -> bool:
        """Start a definition if ``lines`` hold ``B#.n`` / ``L#.n``; True when they do."""
        heads = [s for line in lines for s in line.statements if isinstance(s, ast.BankBegin)]
        if not heads:
            return False
        head = heads[0]
        motor = self.motors.get(head.motor or ctx.default_motor)
        if len(lines) != 1 or len(lines[0].statements) != 1 or lines[0].joined:
            (motor or self.motors[1]).report_error(ctx, CmlSyntaxError(
                "a bank header stands alone on its line", text=lines[0].source))
            return True
        session = _Session(motor, head.ladder, head.index)
        self._sessions[(ctx.origin, ctx.session)] = session
        if motor is not None:
            self._open(session, ctx)
        return True

    def _open(self, session: _Session, ctx: Context) -> None:
        motor = session.motor
        assert motor is not None
        try:
            if not 1 <= session.number <= motor.banks.count(session.ladder):
                raise OutOfRangeError(f"bank number {session.number}")
            motor.banks.begin(session.ladder, session.number)
        except MotorError as error:
            session.failed = True
            motor.report_error(ctx, error)

    def consume(self, text: str, ctx: Context) -> bool:
        """Feed a line to the definition in progress; False when there is none."""
        session = self._sessions.get((ctx.origin, ctx.session))
        if session is None:
            return False
        if not text.strip(" \t"):
            self._finish(ctx)
            return True
        try:
            lines = parse(text)
        except CmlSyntaxError as error:
            self._fail(session, ctx, error)
            return True
        if any(isinstance(s, ast.BankEnd) for line in lines for s in line.statements):
            self._end_line(lines, session, ctx, text)
            return True
        if session.motor is not None and not session.failed:
            self._store(session, ctx, text, lines)
        return True

    def _end_line(self, lines: list[ast.Line], session: _Session, ctx: Context,
                  text: str) -> None:
        if len(lines) == 1 and len(lines[0].statements) == 1:
            self._finish(ctx)
            return
        self._fail(session, ctx, CmlSyntaxError("END stands alone on its line", text=text))
        self._finish(ctx)

    def _store(self, session: _Session, ctx: Context, text: str,
               lines: list[ast.Line]) -> None:
        motor = session.motor
        assert motor is not None
        try:
            _check_comment(text, motor.firmware)
            filled = [fill_motor(line, motor.id) for line in lines]
            pending = session.pending_condition
            for line in filled:
                check_line(line, ladder=session.ladder, firmware=motor.firmware)
                if pending and (len(line.statements) > 2
                                or any(isinstance(s, ast.Branch) for s in line.statements)):
                    raise CmlSyntaxError("a branch has at most 3 elements", text=line.source)
                pending = condition_only(line)
            motor.banks.append(session.ladder, session.number, filled)
            session.pending_condition = pending
        except MotorError as error:
            self._fail(session, ctx, error)

    def _fail(self, session: _Session, ctx: Context, error: MotorError) -> None:
        if session.failed or session.motor is None:
            return
        session.failed = True
        session.motor.report_error(ctx, error)

    def _finish(self, ctx: Context) -> None:
        session = self._sessions.pop((ctx.origin, ctx.session))
        motor = session.motor
        if motor is None or session.failed:
            return
        if motor.reports(Report.MESSAGES):
            motor.say(ctx, END_OF_BANK, kind="message")


def _check_comment(text: str, firmware: Firmware) -> None:
    """RT3 1.1 "/": comments cannot be used inside any banks (CM2 drops them, 2.2.2 "//")."""
    if firmware.max_bank_steps is None:
        return
    _, code_end = scan(text)
    if text[code_end:].strip(" \t"):
        raise CmlSyntaxError("no comments inside RT3 banks", text=text, position=code_end)
