"""``coolmuscle check``: a linter for CML files, for editors and CI.

Rules (``rule`` id, severity, the motor's error number where the motor has one):

==================  ========  =====  =====================================================
rule                severity  error  what (manual section)
==================  ========  =====  =====================================================
syntax              error     01     the line does not parse (CML 6.3-6.9; the one parser)
statement-length    error     --     more than 40 characters between commas in a bank
                                     (RT3 3.3.2)
too-many-commands   error     02     CM2: more than 500 bank commands per motor (2.2.2)
too-many-steps      error     02     RT3/CM1: more than 200 steps per motor (RT3 1, 3.4)
bank-number         error     00     bank number outside 1..30 (2.2.2 "B", 2.2.3 "L")
bank-end            error     --     a bank definition the file never ends (2.2.2 "END")
not-in-bank         error     03     a command banks cannot hold (2.2.2 "Execute
                                     Commands", 6.5, 6.6, 4.5.1 "X" in a ladder bank;
                                     ``^`` is allowed in RT3 banks, RT3 7.1-7.3)
cannot-follow       error     04     C J CL JL X X- W followed by another command,
                                     X / X- not first on the line, W in a branch's else
                                     part, a motion of a motor after its Y/Q/Z on one
                                     line (2.2.2, 4.3.2, error04)
wait-outside-branch error     01     W not in the then part of a branch (2.2.2 "W")
comment-in-bank     error     01     RT3: a comment inside a bank (RT3 1.1 "/")
missing-bank        error     05/06  C/J (CL/JL) to a bank the file does not define
cross-motor-call    error     --     C/J/CL/JL naming another motor's bank (2.2.2 "C")
recursion           error     --     a bank that calls itself through C/CL (2.2.2 "C")
nesting             error     --     calls or X loops nested deeper than 10 (2.2.2, 4.2.5)
loop-balance        error     --     X without X- or X- without X (2.2.2 "X")
range               error     00     memory number, K number or literal value out of
                                     range (6.1, 6.2), motor ID outside 1..15
register-unset      warning   --     a register a bank reads that nothing sets (RT3 1.2;
                                     index 0, the direct data, and T0 "no action" excepted)
literal-in-bank     warning   --     a number in a bank's assignment or condition (RT3 1.2:
                                     an error, error01, on RT3 and CM1 firmware)
bank-not-in-file    warning   --     ``[#``/``[L#`` of a bank this file does not define
motor-id            warning   --     a motor ID beyond ``--motors``
no-such-input       warning   --     an ``I#`` beyond the motor's inputs (it reads OFF;
                                     RT3 1.1 "used with I1-I4"; docs/fidelity.md)
==================  ========  =====  =====================================================

Counting (RT3 3.4 "1 step is considered any command other than operands, math symbols
and carriage returns. These include the start of the bank"): a bank header is one
step, every statement one, every register or input an expression reads one; numbers,
strings, operators, functions and ``END`` are none (this reproduces the manual's 1, 4,
6 and 7 step examples).  CM2 commands (2.2.2 "500 commands"): every statement of a
bank body, a branch counting its condition and each action.
"""

from __future__ import annotations

from typing import Final

from ...client.program import BankBlock, ProgramFile, SourceLine
from ...cml import ast
from ...cml.scanner import scan
from ...errors import CmlSyntaxError, OutOfRangeError
from ...motor.state.firmware import Firmware, get_firmware
from ...motor.state.memory import Memory
from . import tree
from .report import RULES, BankSummary, CheckReport, Diagnostic, Severity
from .tree import RegKey

__all__ = ["Diagnostic", "BankSummary", "CheckReport", "check_program", "RULES"]

#: RT3 3.3.2: characters between a comma and the line end.
MAX_STATEMENT_CHARS: Final = 40
#: 2.2.2 "X" and "C", 4.2.5: loops and calls nest up to 10 levels.
MAX_NESTING: Final = 10

_NOT_IN_BANK_EXEC: Final = {"pause_motor": "]1", "next_line": ">", "prev_line": "<",
                            "stop_after_line": "}", "save": "$"}
_DATA_KINDS: Final = ("P", "S", "A", "M", "T", "V", "N", "R", "H")
#: Statements after which nothing may follow in their list (error04).
_LINE_ENDERS: Final = (ast.Call, ast.Loop, ast.LoopEnd, ast.Wait)


class _Checker:
    """One pass over a program file; fills a :class:`CheckReport`."""

    def __init__(self, program: ProgramFile, fw: Firmware, motors: int | None) -> None:
        self.program = program
        self.fw = fw
        self.motors = motors
        self.report = CheckReport(program.path, fw.name)
        self.rt3 = fw.max_bank_steps is not None   # RT3 and CM1 bank rules
        self.memory = Memory(fw)
        #: (start, end) of the statement being checked in its line (``None``: the line)
        self._span: tuple[int, int] | None = None
        self.defined: dict[tuple[bool, int, int], BankBlock] = {}
        for block in program.banks:
            self.defined.setdefault((block.ladder, block.number, block.motor_id), block)

    def run(self) -> CheckReport:
        for line in self.program.source_lines:
            if line.error is not None:
                self._syntax(line, line.error)
            flat = [each for statement in line.statements for each in tree.flat(statement)]
            parts = _parts(line.raw) if flat else []
            for i, each in enumerate(flat):
                # each statement's diagnostics point into its own part of the line
                self._span = parts[i] if len(parts) == len(flat) else None
                self._ranges(line, each)
            self._span = None
        set_before: set[RegKey] = set()
        for item in self.program.items:
            if isinstance(item, BankBlock):
                self._bank(item, set_before)
            else:
                self._direct(item, set_before)
        self._limits()
        self._calls()
        self.report.diagnostics.sort(key=lambda d: (d.line, d.column))
        return self.report

    # -- per line ------------------------------------------------------------------------
    def _column(self, line: SourceLine, needle: str) -> int:
        """The 1-based column of ``needle`` in the statement being checked (its first
        occurrence there; in the whole line when no statement is being checked)."""
        if self._span is not None and needle:
            start, end = self._span
            found = line.raw.upper().find(needle.upper(), start, end)
            if found >= 0:
                return found + 1
        return tree.column(line.raw, needle)

    def _syntax(self, line: SourceLine, error: CmlSyntaxError) -> None:
        message = str(error).split(" at column ")[0]
        self.report.add(line, "syntax", message, column=error.position + 1)

    def _ranges(self, line: SourceLine, statement: ast.Statement) -> None:
        self._inputs(line, statement)
        motor = getattr(statement, "motor", None)
        if isinstance(statement, ast.Assign):
            motor = statement.target.motor
            self._assignment(line, statement)
        elif isinstance(statement, ast.Ref):
            motor = statement.reg.motor
            self._register(line, statement.reg)
        if motor is not None:
            if not 1 <= motor <= 15:
                self.report.add(line, "range", f"motor ID {motor} is not 1..15",
                                column=self._column(line, f".{motor}") + 1)
            elif self.motors is not None and motor > self.motors:
                self.report.add(line, "motor-id", f"motor ID {motor} is beyond the "
                                f"{self.motors} motor(s) of the chain",
                                column=self._column(line, f".{motor}") + 1)
        if isinstance(statement, (ast.BankBegin, ast.StartBank, ast.Call)):
            ladder = getattr(statement, "ladder", None)
            if ladder is None:
                ladder = getattr(statement, "kind", "B") in ("L", "LM", "CL", "JL")
            self._bank_number(line, statement.index, ladder)

    def _inputs(self, line: SourceLine, statement: ast.Statement) -> None:
        """``I#`` conditions beyond the firmware's inputs (they read OFF)."""
        exprs: list[ast.Expr] = []
        if isinstance(statement, ast.Branch):
            exprs.append(statement.condition)
        elif isinstance(statement, (ast.Assign, ast.OutputWord)):
            exprs.append(statement.value)
        for expr in exprs:
            for ref in tree.expr_regs(expr):
                if isinstance(ref, ast.Input) and not 1 <= ref.index <= self.fw.inputs:
                    self.report.add(line, "no-such-input", f"I{ref.index}: the motor has "
                                    f"inputs I1..I{self.fw.inputs} ({self.fw.name}); it "
                                    "reads OFF", column=self._column(line, f"I{ref.index}"))

    def _bank_number(self, line: SourceLine, number: int | None, ladder: bool) -> None:
        top = self.fw.ladder_banks if ladder else self.fw.program_banks
        if number is not None and not 1 <= number <= top:
            kind = "ladder" if ladder else "program"
            self.report.add(line, "bank-number", f"{kind} bank {number} does not exist "
                            f"(1..{top})", column=self._column(line, str(number)))

    def _register(self, line: SourceLine, reg: ast.Reg) -> bool:
        text = tree.reg_text(reg.kind, reg.index, reg.motor)
        if reg.kind == "K":
            try:
                self.fw.spec(reg.number)
            except KeyError:
                self.report.add(line, "range", f"K{reg.number} does not exist (K20..K89)",
                                column=self._column(line, text))
                return False
            return True
        top = self.fw.registers.limit(reg.kind)
        if reg.kind in ("P", "N", "R") and self.fw.can_allocate and self.fw.pnr_pool:
            top = self.fw.pnr_pool
        if reg.number > top:
            self.report.add(line, "range", f"{reg.kind}{reg.number} does not exist "
                            f"({reg.kind}0..{reg.kind}{top} on {self.fw.name})",
                            column=self._column(line, text))
            return False
        return True

    def _assignment(self, line: SourceLine, statement: ast.Assign) -> None:
        target = statement.target
        if not self._register(line, target) or statement.op != "=":
            return
        value = statement.value
        literal = value.value if isinstance(value, ast.Num) else \
            value.text if isinstance(value, ast.Str) and target.kind == "V" else None
        if literal is None:
            return
        try:
            if target.kind == "K":
                self.fw.spec(target.number).check(literal)
            else:
                self.memory.normalise(target.kind, literal)
        except OutOfRangeError as error:
            reg = tree.reg_text(target.kind, target.index, target.motor)
            self.report.add(line, "range", f"{reg}={literal}: {error}",
                            column=self._column(line, target.kind))

    def _direct(self, line: SourceLine, set_before: set[RegKey]) -> None:
        for statement in line.statements:
            for each in tree.flat(statement):
                for reg in tree.writes(each):
                    set_before.add(tree.key(reg, 1))
                if isinstance(each, ast.StartBank) and each.index is not None:
                    ladder = each.kind != "B"
                    motor = each.motor or 1
                    if (ladder, each.index, motor) not in self.defined:
                        kind = "ladder" if ladder else "program"
                        self.report.add(line, "bank-not-in-file", f"{kind} bank {each.index} "
                                        f"of motor {motor} is not defined in this file",
                                        column=tree.column(line.raw, "["))
                if isinstance(each, ast.BankEnd):
                    self.report.add(line, "bank-end", "END outside a bank definition")

    # -- per bank ------------------------------------------------------------------------
    def _bank(self, block: BankBlock, set_before: set[RegKey]) -> None:
        motor = block.motor_id
        steps, commands, depth = 1, 0, 0
        if block.closed_by == "eof":
            self.report.add(block.header, "bank-end", f"{block.label} is never ended "
                            "(END or an empty line)")
        set_in_banks = self._set_in_banks()
        flagged: set[RegKey] = set()
        for line in block.body:
            self._length(line)
            self._comment(line)
            for logical in line.lines:
                self._sequence(line, logical.statements, None, motor)
            for statement in line.statements:
                steps += tree.steps(statement)
                commands += tree.commands(statement)
                self._literal(line, statement)
                for each in tree.flat(statement):
                    depth = self._loops(block, line, each, depth)
                    self._allowed(block, line, each)
                    self._unset(line, each, motor, set_before | set_in_banks, flagged)
        if depth > 0:
            self.report.add(block.header, "loop-balance", f"{block.label}: {depth} X loop(s) "
                            "without X-")
        self.report.banks.append(BankSummary(motor, block.kind, block.number,
                                             block.header.number, steps, commands))

    def _set_in_banks(self) -> set[RegKey]:
        """Registers some bank of the file writes (ladder banks set them for programs);
        worked out once a file (it was once a bank: quadratic in the banks)."""
        cached: set[RegKey] | None = getattr(self, "_banks_write", None)
        if cached is not None:
            return cached
        found: set[RegKey] = set()
        for block in self.program.banks:
            for line in block.body:
                for statement in line.statements:
                    for each in tree.flat(statement):
                        found |= {tree.key(r, block.motor_id) for r in tree.writes(each)}
        self._banks_write: set[RegKey] | None = found
        return found

    def _length(self, line: SourceLine) -> None:
        for piece in _split_commas(line.send):
            if len(piece.strip()) > MAX_STATEMENT_CHARS:
                self.report.add(line, "statement-length", f"{len(piece.strip())} characters "
                                f"between commas (at most {MAX_STATEMENT_CHARS})",
                                column=tree.column(line.raw, piece.strip()[:10]))

    def _loops(self, block: BankBlock, line: SourceLine, statement: ast.Statement,
               depth: int) -> int:
        if isinstance(statement, ast.Loop):
            depth += 1
            if depth > MAX_NESTING:
                self.report.add(line, "nesting", f"X loops nested {depth} deep "
                                f"(at most {MAX_NESTING})", column=tree.column(line.raw, "X"))
        elif isinstance(statement, ast.LoopEnd):
            if depth == 0:
                self.report.add(line, "loop-balance", "X- without an open X loop",
                                column=tree.column(line.raw, "X"))
                return 0
            depth -= 1
        return depth

    def _allowed(self, block: BankBlock, line: SourceLine, statement: ast.Statement) -> None:
        """error03: 2.2.2/2.2.3 "]1, [L, ]L, >, <, }, $ commands can not be used", 6.5, 6.6."""
        what: str | None = None
        if isinstance(statement, ast.Exec) and statement.op in _NOT_IN_BANK_EXEC:
            what = _NOT_IN_BANK_EXEC[statement.op]
        elif isinstance(statement, ast.Exec) and statement.op == "go" and not self.rt3:
            what = "^"                      # 6.5 "^": P x, L x (RT3 7.1-7.3 use it)
        elif isinstance(statement, ast.StartBank) and statement.kind != "B" \
                and not block.ladder:
            what = "[" + statement.kind
        elif isinstance(statement, ast.StopBank) and not block.ladder:
            what = "]" + statement.kind
        elif isinstance(statement, ast.Query) and (statement.letter is not None
                                                   or statement.number in (999, 1000)):
            what = "?" + (statement.letter or str(statement.number))
        elif isinstance(statement, (ast.BankBegin, ast.ClearBanks, ast.Alloc)):
            what = "a bank definition" if isinstance(statement, ast.BankBegin) else \
                "B100/L100" if isinstance(statement, ast.ClearBanks) else "\\P/\\N"
        elif isinstance(statement, (ast.Loop, ast.LoopEnd)) and block.ladder:
            what = "X (ladder banks are scanned, 4.5.1)"
        elif isinstance(statement, ast.Move) and block.ladder:
            what = statement.kind + " (a ladder bank does not move the motor, 6.3)"
        if what is not None:
            self.report.add(line, "not-in-bank", f"{what} is not allowed in {block.label}",
                            column=tree.column(line.raw, what[:2]))

    def _sequence(self, line: SourceLine, statements: tuple[ast.Statement, ...],
                  head: str | None, motor: int = 1) -> None:
        """error04: C J CL JL X X- W end their list; X and X- start the line (2.2.2);
        W waits in a branch's then part only; after Y/Q/Z a motor moves no more on the
        line (4.3.2)."""
        moved: dict[int, str] = {}
        for i, statement in enumerate(statements):
            if isinstance(statement, ast.Branch):
                self._sequence(line, statement.then, "then", motor)
                self._sequence(line, statement.orelse, "else", motor)
                continue
            if isinstance(statement, ast.Wait) and head != "then":
                rule = "cannot-follow" if head == "else" else "wait-outside-branch"
                self.report.add(line, rule, "W waits in the then part of a branch only",
                                column=tree.column(line.raw, "W"))
            if isinstance(statement, (ast.Loop, ast.LoopEnd)) and (i > 0 or head):
                self.report.add(line, "cannot-follow", "X / X- must begin the line",
                                column=tree.column(line.raw, "X"))
            if isinstance(statement, _LINE_ENDERS) and i + 1 < len(statements):
                text = tree.statement_text(statement)
                self.report.add(line, "cannot-follow", f"{text} cannot be followed by "
                                "another command", column=tree.column(line.raw, text))
            self._motion(line, statement, moved, motor)

    def _motion(self, line: SourceLine, statement: ast.Statement, moved: dict[int, str],
                default: int) -> None:
        if isinstance(statement, ast.Ref) and statement.reg.kind == "P":
            kind, who = "P", statement.reg.motor
        elif isinstance(statement, (ast.Move, ast.Interp)):
            kind = statement.kind if isinstance(statement, ast.Move) else "@"
            who = statement.motor
        else:
            return
        who = who or default
        if who in moved:
            self.report.add(line, "cannot-follow", f"{moved[who]} of motor {who} cannot be "
                            f"followed by another motion of it ({kind}) on one line (4.3.2)",
                            column=tree.column(line.raw, kind))
        elif kind in ("Y", "Q", "Z"):
            moved[who] = kind

    def _comment(self, line: SourceLine) -> None:
        """RT3 1.1 "/": "comments cannot be used inside any banks"."""
        if not self.rt3 or line.error is not None:
            return
        _tokens, code_end = scan(line.raw)
        if line.raw[code_end:].strip():
            self.report.add(line, "comment-in-bank", "comments are not allowed inside banks "
                            "on RT3 (RT3 1.1)", column=code_end + 1
                            + len(line.raw[code_end:]) - len(line.raw[code_end:].lstrip()))

    def _literal(self, line: SourceLine, statement: ast.Statement) -> None:
        """RT3 1.2: "you cannot set it in the bank with an actual number"."""
        exprs: list[ast.Expr] = []
        if isinstance(statement, (ast.Assign, ast.OutputWord)):
            if isinstance(statement, ast.Assign) and statement.target.kind == "K" \
                    and not self.rt3:
                return
            exprs.append(statement.value)
        elif isinstance(statement, ast.Branch):
            exprs.append(statement.condition)
            for inner in statement.then + statement.orelse:
                self._literal(line, inner)
        number = next((n for e in exprs for n in tree.numbers(e)), None)
        if number is None:
            return
        severity: Severity = "error" if self.rt3 else "warning"
        self.report.add(line, "literal-in-bank", f"the number {number} is used inside a "
                        "bank; set a register before the bank and use it (RT3 1.2)",
                        column=tree.column(line.raw, str(number)), severity=severity,
                        motor_error=1 if self.rt3 else None)

    def _unset(self, line: SourceLine, statement: ast.Statement, motor: int,
               known: set[RegKey], flagged: set[RegKey]) -> None:
        for reg in tree.reads(statement):
            key = tree.key(reg, motor)
            if reg.kind in _DATA_KINDS and reg.number and key not in known \
                    and key not in flagged:
                flagged.add(key)
                text = tree.reg_text(reg.kind, reg.index, reg.motor)
                self.report.add(line, "register-unset", f"{text} is used in the bank but "
                                "never set before it (RT3 1.2)", column=tree.column(line.raw, text))

    # -- whole file ----------------------------------------------------------------------
    def _limits(self) -> None:
        per_motor: dict[int, tuple[int, int, int]] = {}
        for bank in self.report.banks:
            steps, commands, first = per_motor.get(bank.motor, (0, 0, bank.line))
            per_motor[bank.motor] = (steps + bank.steps, commands + bank.commands, first)
        for motor, (steps, commands, first) in per_motor.items():
            if self.fw.max_bank_steps is not None and steps > self.fw.max_bank_steps:
                self.report.add(first, "too-many-steps", f"motor {motor}: {steps} steps in "
                                f"banks (at most {self.fw.max_bank_steps} on {self.fw.name})")
            if self.fw.max_bank_commands is not None and commands > self.fw.max_bank_commands:
                self.report.add(first, "too-many-commands", f"motor {motor}: {commands} "
                                f"bank commands (at most {self.fw.max_bank_commands})")

    def _calls(self) -> None:
        from .calls import check_calls
        check_calls(self.program, self.defined, self.report, self.rt3)


def _split_commas(code: str) -> list[str]:
    """The pieces between commas, ignoring commas inside strings."""
    pieces: list[str] = []
    current: list[str] = []
    quoted = False
    for ch in code:
        if ch == '"':
            quoted = not quoted
        if ch in ",;" and not quoted:
            pieces.append("".join(current))
            current = []
        else:
            current.append(ch)
    pieces.append("".join(current))
    return pieces


def _parts(raw: str) -> list[tuple[int, int]]:
    """(start, end) of each part of a line between the separators ``,`` ``:`` ``;``
    outside parentheses: one a statement, a branch's condition or one of its actions
    (the order of :func:`tree.flat`).  ``[]`` when the line does not scan."""
    try:
        toks, _ = scan(raw)
    except CmlSyntaxError:
        return []
    parts: list[tuple[int, int]] = []
    depth, start = 0, -1
    for tok in toks:
        if tok.kind == "(":
            depth += 1
        elif tok.kind == ")":
            depth -= 1
        if tok.kind == "eof" or (depth == 0 and tok.kind in (",", ":", ";")):
            if start >= 0:
                parts.append((start, tok.start))
            start = -1
        elif start < 0:
            start = tok.start
    return parts


def check_program(program: ProgramFile, *, firmware: str | None = None,
                  motors: int | None = None) -> CheckReport:
    """Lint ``program`` for ``firmware`` (default: the file's magic comment, else cm2)."""
    fw = get_firmware(firmware or program.firmware or "cm2")
    return _Checker(program, fw, motors if motors is not None else program.motors).run()

