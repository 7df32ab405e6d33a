"""``coolmuscle check`` output: the human form (one line per finding, as compilers print
them, so editors can jump to it) and the JSON form of docs/check-schema.json."""

from __future__ import annotations

from typing import Any

from ...motor.state.firmware import get_firmware
from .lint import CheckReport

__all__ = ["to_json", "format_human", "SCHEMA_VERSION"]

SCHEMA_VERSION = 1


def _motors(report: CheckReport) -> list[dict[str, Any]]:
    fw = get_firmware(report.firmware)
    totals: dict[int, list[int]] = {}
    for bank in report.banks:
        entry = totals.setdefault(bank.motor, [0, 0])
        entry[0] += bank.steps
        entry[1] += bank.commands
    return [{"motor": motor, "steps": steps, "commands": commands,
             "step_limit": fw.max_bank_steps, "command_limit": fw.max_bank_commands}
            for motor, (steps, commands) in sorted(totals.items())]


def _file(report: CheckReport) -> dict[str, Any]:
    return {
        "path": report.path, "firmware": report.firmware,
        "errors": report.errors, "warnings": report.warnings,
        "diagnostics": [{"line": d.line, "column": d.column, "severity": d.severity,
                         "rule": d.rule, "message": d.message,
                         "motor_error": d.motor_error} for d in report.diagnostics],
        "banks": [{"motor": b.motor, "kind": b.kind, "number": b.number, "line": b.line,
                   "steps": b.steps, "commands": b.commands} for b in report.banks],
        "motors": _motors(report),
    }


def to_json(reports: list[CheckReport], *, strict: bool = False) -> dict[str, Any]:
    """The JSON document (docs/check-schema.json) for ``reports``."""
    errors = sum(r.errors for r in reports)
    warnings = sum(r.warnings for r in reports)
    return {"version": SCHEMA_VERSION, "ok": errors == 0 and not (strict and warnings),
            "errors": errors, "warnings": warnings, "files": [_file(r) for r in reports]}


def _plural(count: int, word: str) -> str:
    return f"{count} {word}{'' if count == 1 else 's'}"


def format_human(report: CheckReport) -> list[str]:
    """``path:line:col: severity[rule] message (errorNN)`` lines and a summary line."""
    lines = [d.format(report.path) for d in report.diagnostics]
    counts = []
    for motor in _motors(report):
        limit = motor["step_limit"] if motor["step_limit"] is not None else \
            motor["command_limit"]
        used = motor["steps"] if motor["step_limit"] is not None else motor["commands"]
        unit = "steps" if motor["step_limit"] is not None else "commands"
        counts.append(f"motor {motor['motor']}: {used}/{limit} {unit}")
    banks = _plural(len(report.banks), "bank")
    summary = f"{report.path}: {_plural(report.errors, 'error')}, " \
              f"{_plural(report.warnings, 'warning')}; {banks} ({report.firmware})"
    if counts:
        summary += "; " + ", ".join(counts)
    return lines + [summary]
