"""What ``coolmuscle check`` reports: rules, diagnostics and the per-file report.

The rule table is documented in :mod:`.check`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final, Literal

from ...client.program import SourceLine

__all__ = ["RULES", "BankSummary", "CheckReport", "Diagnostic", "Severity"]

Severity = Literal["error", "warning"]

#: rule -> (severity, the motor's error number or None)
RULES: Final[dict[str, tuple[Severity, int | None]]] = {
    "syntax": ("error", 1), "statement-length": ("error", None),
    "script": ("error", None),      # a script line coolmuscle run refuses (docs/scripts.md)
    "too-many-commands": ("error", 2), "too-many-steps": ("error", 2),
    "bank-number": ("error", 0), "bank-end": ("error", None),
    "not-in-bank": ("error", 3), "cannot-follow": ("error", 4),
    "wait-outside-branch": ("error", 1),
    "comment-in-bank": ("error", 1), "missing-bank": ("error", 5),
    "cross-motor-call": ("error", None), "recursion": ("error", None),
    "nesting": ("error", None), "loop-balance": ("error", None), "range": ("error", 0),
    "register-unset": ("warning", None), "literal-in-bank": ("warning", None),
    "bank-not-in-file": ("warning", None), "motor-id": ("warning", None),
    "no-such-input": ("warning", None),
}


@dataclass(frozen=True)
class Diagnostic:
    """One finding: 1-based line and column, severity, rule, message, motor error."""

    line: int
    column: int
    severity: Severity
    rule: str
    message: str
    motor_error: int | None = None

    def format(self, path: str) -> str:
        number = f" (error{self.motor_error:02d})" if self.motor_error is not None else ""
        return f"{path}:{self.line}:{self.column}: {self.severity}[{self.rule}] " \
               f"{self.message}{number}"


@dataclass
class BankSummary:
    """One bank of the file: where it is and what it counts."""

    motor: int
    kind: str
    number: int
    line: int
    steps: int
    commands: int


@dataclass
class CheckReport:
    """Everything ``check`` found in one file."""

    path: str
    firmware: str
    diagnostics: list[Diagnostic] = field(default_factory=list)
    banks: list[BankSummary] = field(default_factory=list)

    @property
    def errors(self) -> int:
        return sum(d.severity == "error" for d in self.diagnostics)

    @property
    def warnings(self) -> int:
        return sum(d.severity == "warning" for d in self.diagnostics)

    def add(self, line: SourceLine | int, rule: str, message: str, *, column: int = 1,
            motor_error: int | None = None, severity: Severity | None = None) -> None:
        default, number = RULES[rule]
        severity = severity or default
        self.diagnostics.append(Diagnostic(
            line if isinstance(line, int) else line.number, column, severity, rule, message,
            number if motor_error is None else motor_error))
