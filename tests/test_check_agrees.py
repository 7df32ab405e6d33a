"""``coolmuscle check`` and the motor agree on every bank line the manuals print.

For each line of tests/data/cml_manual_corpus.txt (and a few more that break the bank
rules), stored in a program bank and in a ladder bank, on CM2 and on RT3: the motor's
own bank rules (:func:`coolmuscle.motor.programs.bankcheck.check_line`) refuse it with error NN
exactly when ``check`` reports an error with that number on it.  Rules that need more
than one line (missing banks), the file's comments and value ranges are left out.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from coolmuscle.client.program import parse_program
from coolmuscle.cml import ast
from coolmuscle.cml.parser import parse
from coolmuscle.errors import CmlSyntaxError, MotorError
from coolmuscle.motor.programs.bankcheck import check_line, fill_motor
from coolmuscle.motor.state.firmware import get_firmware
from coolmuscle.tools.check.lint import check_program

ROOT = Path(__file__).resolve().parents[1]
ROWS = [row.split("\t")[2] for row in
        (ROOT / "tests" / "data" / "cml_manual_corpus.txt").read_text().splitlines()
        if row and not row.startswith("#")]
EXTRA = ["X3.1, P1.1", "P1.1, X3.1", "C2.1, P1.1", "I1.1, W1.1, ?99.1", "W1.1",
         "I1.1, ?99.1, W1.1", "Y2.1, P3.1", "P1.1, Y2.1, P2.1", "^.1", "[L2.1", "]L.1",
         "$.1", "?1000", "V1==5, C2, T0", "A1.1=100", "S1.1=U2(V1)+1", "K23.1=13"]
LEFT_OUT = ("missing-bank", "comment-in-bank", "range")


def _bank_lines() -> list[str]:
    out = []
    for text in ROWS + EXTRA:
        try:
            lines = parse(text)
        except CmlSyntaxError:
            continue
        if lines and not any(isinstance(s, (ast.BankBegin, ast.BankEnd, ast.ClearBanks))
                             for line in lines for s in line.statements):
            out.append(text)
    return out


@pytest.mark.parametrize("firmware", ["cm2", "rt3"])
@pytest.mark.parametrize("ladder", [False, True], ids=["program", "ladder"])
def test_check_reports_the_error_the_motor_gives(firmware: str, ladder: bool) -> None:
    fw = get_firmware(firmware)
    disagree = []
    for text in _bank_lines():
        motor: int | None = None
        try:
            for line in parse(text):
                check_line(fill_motor(line, 1), ladder=ladder, firmware=fw)
        except MotorError as error:
            motor = error.number
        source = f"{'L' if ladder else 'B'}1.1\n{text}\nEND\n"
        found = {d.motor_error for d in check_program(parse_program(source),
                                                      firmware=firmware).diagnostics
                 if d.line == 2 and d.severity == "error" and d.rule not in LEFT_OUT
                 and d.motor_error is not None}
        if (motor is None and found) or (motor is not None and motor not in found):
            disagree.append((text, motor, sorted(found)))
    assert disagree == []


def test_step_and_command_counts_match_the_motor_s() -> None:
    """Every bank of examples/: the counts ``check`` prints are the bank model's."""
    from coolmuscle.client.program import load_program
    from coolmuscle.motor.programs.bankcheck import line_commands, line_steps
    for path in sorted((ROOT / "examples").glob("*.cml")):
        program = load_program(path)
        report = check_program(program)
        for block, summary in zip(program.banks, report.banks):
            lines = [fill_motor(l, block.motor_id) for s in block.body for l in s.lines]
            assert summary.steps == 1 + sum(map(line_steps, lines)), (path.name, block.label)
            assert summary.commands == sum(map(line_commands, lines)), (path.name, block.label)
