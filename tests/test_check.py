"""``coolmuscle check``: the manuals' programs pass, one bad program per rule fails.

Good corpus: every example of examples/ (the manuals' sample programs) and every line
of tests/data/cml_manual_corpus.txt.  Bad corpus: tests/data/check/RULE.cml, each with
``# expect: RULE LINE:COL [errorNN]`` headers naming exactly what it must report.  All
JSON output is validated against docs/check-schema.json.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coolmuscle.client.program import parse_program
from coolmuscle.tools.check.lint import RULES, check_program
from coolmuscle.tools.check.output import format_human, to_json
from coolmuscle.tools.cli import app as cli
from fixtures import run_coolmuscle

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.cml"))
BAD = sorted((ROOT / "tests" / "data" / "check").glob("*.cml"))
SCHEMA = json.loads((ROOT / "docs" / "check-schema.json").read_text())
CORPUS = ROOT / "tests" / "data" / "cml_manual_corpus.txt"
_EXPECT = re.compile(r"# expect: (\S+) (\d+):(\d+)(?: error(\d\d))?")


def check_cli(capsys: Any, *args: str) -> tuple[int, str]:
    with pytest.raises(SystemExit) as exit_:
        cli.main(["check", *args])
    out, _ = capsys.readouterr()
    return int(exit_.value.code or 0), out


VALIDATOR = jsonschema.Draft202012Validator(SCHEMA)


def validate(document: dict[str, Any]) -> None:
    VALIDATOR.validate(document)


def test_every_rule_has_a_bad_program() -> None:
    assert {path.stem for path in BAD} == set(RULES)


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_the_manuals_examples_pass(path: Path, capsys: Any) -> None:
    code, out = check_cli(capsys, str(path), "--format", "json")
    document = json.loads(out)
    validate(document)
    assert code == 0 and document["ok"] and document["errors"] == 0, out
    assert not [d for d in document["files"][0]["diagnostics"] if d["severity"] == "error"]


def test_every_manual_line_is_free_of_syntax_errors_unless_marked_wrong() -> None:
    for row in CORPUS.read_text(encoding="utf-8").splitlines():
        if not row or row.startswith("#"):
            continue
        section, expectation, line = row.split("\t", 2)
        text = f"{line}, ?99, ?98" if expectation == "cond" else line
        report = check_program(parse_program(text + "\n"))
        syntax = [d for d in report.diagnostics if d.rule == "syntax"]
        assert bool(syntax) == (expectation == "fail"), (section, line, syntax)
        for diagnostic in syntax:
            assert diagnostic.motor_error == 1 and diagnostic.column >= 1


@pytest.mark.parametrize("path", BAD, ids=lambda p: p.stem)
def test_each_rule_is_reported_where_it_is_broken(path: Path, capsys: Any) -> None:
    expected = {(m.group(1), int(m.group(2)), int(m.group(3)),
                 int(m.group(4)) if m.group(4) else None)
                for m in _EXPECT.finditer(path.read_text())}
    assert expected, f"{path} has no '# expect:' header"
    code, out = check_cli(capsys, str(path), "--format", "json")
    document = json.loads(out)
    validate(document)
    found = {(d["rule"], d["line"], d["column"], d["motor_error"])
             for d in document["files"][0]["diagnostics"]}
    assert found == expected
    severity = RULES[path.stem][0]
    assert code == (1 if severity == "error" else 0)
    assert check_cli(capsys, str(path), "--strict")[0] == 1


def test_human_output_is_one_line_per_finding_and_a_summary(capsys: Any) -> None:
    path = ROOT / "tests" / "data" / "check" / "missing-bank.cml"
    code, out = check_cli(capsys, str(path))
    assert code == 1
    assert out.splitlines() == [
        f"{path}:3:13: error[missing-bank] C5 goes to program bank 5 of motor 1, which this "
        "file does not define (error05)",
        f"{path}: 1 error, 0 warnings; 2 banks (cm2); motor 1: 4/500 commands"]


def test_step_counts_follow_rt3_3_4() -> None:
    """The manual's examples: 1 step, 4 steps, 7 steps (two banks), 6 steps (3.6)."""
    def steps(text: str) -> list[int]:
        report = check_program(parse_program(text), firmware="rt3")
        return [bank.steps for bank in report.banks]
    assert steps("L1.1\nEND.1\n") == [1]
    assert steps("L1.1\nV1=V2+V3\nEND.1\n") == [4]
    assert steps("L1.1\nV1==P1,S0,CL2\nEND.1\nL2.1\nM0\nEND.1\n") == [5, 2]
    assert steps("L1\nV1=V1+V2\nV3=U2(V1)\nEND\n") == [6]


def test_each_statement_is_reported_at_its_own_column() -> None:
    """Three statements naming motor 2 on a one-motor chain: three warnings, each at
    its own ``.2`` (not all at the first); a branch's actions too, and a range error
    in the second of two alike statements points at the second."""
    def found(text: str) -> list[tuple[str, int, int]]:
        report = check_program(parse_program(text), motors=1)
        return [(d.rule, d.line, d.column) for d in report.diagnostics]
    assert found("S.2=100, A.2=100, P.2=5\n") == \
        [("motor-id", 1, 3), ("motor-id", 1, 12), ("motor-id", 1, 21)]
    assert found("P1.2=P2.2, S.2=100\n") == [("motor-id", 1, 4), ("motor-id", 1, 14)]
    assert found("P1.1>5, S.2=1:A.3=5, P.2=3\n") == \
        [("motor-id", 1, 11), ("motor-id", 1, 17), ("motor-id", 1, 24)]
    assert found("S.1=5, S.1=40000\n") == [("range", 1, 8)]


def test_loops_nested_deeper_than_10_and_x_in_a_ladder_bank() -> None:
    deep = "B1.1\n" + "X2.1\n" * 11 + "T0.1\n" + "X.1-\n" * 11 + "END\n"
    report = check_program(parse_program(deep))
    assert [(d.rule, d.line) for d in report.diagnostics] == [("nesting", 12)]
    ladder = check_program(parse_program("L1.1\nX2.1\nT0.1\nX.1-\nEND\n"))
    assert [d.rule for d in ladder.diagnostics] == ["not-in-bank", "not-in-bank"]


def test_a_file_with_several_reports_and_the_firmware_option(capsys: Any) -> None:
    paths = [str(ROOT / "examples" / "2.1-operation.cml"),
             str(ROOT / "tests" / "data" / "check" / "range.cml")]
    code, out = check_cli(capsys, *paths, "--format", "json", "--firmware", "rt3")
    document = json.loads(out)
    validate(document)
    assert code == 1 and [f["firmware"] for f in document["files"]] == ["rt3", "rt3"]
    assert document["errors"] == sum(f["errors"] for f in document["files"])


def test_json_of_an_empty_report_is_valid() -> None:
    report = check_program(parse_program(""))
    validate(to_json([report]))
    assert format_human(report) == ["<text>: 0 errors, 0 warnings; 0 banks (cm2)"]


def test_usage_errors_exit_2(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "coolmuscle", "check",
                          str(tmp_path / "missing.cml")], capture_output=True, text=True,
                         env={"PYTHONPATH": str(ROOT / "src"), "PATH": "/usr/bin:/bin"},
                         timeout=60)
    assert out.returncode == 2 and "cannot read" in out.stderr


def test_literals_in_banks_are_errors_on_rt3_and_warnings_on_cm2() -> None:
    text = "V1.1=1\nB1.1\nV1.1==5, C2.1, T0.1\nEND\nB2.1\nEND\n"
    for firmware, severity, number in (("rt3", "error", 1), ("cm2", "warning", None)):
        report = check_program(parse_program(text), firmware=firmware)
        assert [(d.rule, d.severity, d.motor_error, d.column) for d in report.diagnostics] \
            == [("literal-in-bank", severity, number, 7)]


def test_go_in_a_bank_is_allowed_on_rt3_only() -> None:
    text = "L1.1\n^.1\nEND\n"
    assert check_program(parse_program(text), firmware="rt3").diagnostics == []
    assert [d.rule for d in check_program(parse_program(text)).diagnostics] == ["not-in-bank"]


@given(st.lists(st.sampled_from(["B1.1", "L2.1", "END", "", "X3.1", "X.1-", "C2.1", "CL1.1",
                                 "J1.1", "P1.1=5", "V1==5, C3.1", "S1.1, A1.1, P1.1",
                                 "hello", "K44.1=0", "[L9.1", "$.1", "/ comment", "@wait 1",
                                 "# coolmuscle: firmware=rt3", "M0=V2+V5;", "T0"]), max_size=40),
       st.sampled_from(["cm2", "rt3", "cm1"]))
@settings(max_examples=100, deadline=None)
def test_any_file_gives_a_report_that_fits_the_schema(lines: list[str], firmware: str) -> None:
    report = check_program(parse_program("\n".join(lines)), firmware=firmware)
    validate(to_json([report]))
    assert all(1 <= d.line <= max(1, len(lines)) for d in report.diagnostics)


@given(st.text(max_size=300))
@settings(max_examples=200, deadline=None)
def test_arbitrary_text_never_crashes_the_checker(text: str) -> None:
    validate(to_json([check_program(parse_program(text))]))


def test_check_rejects_the_directives_run_rejects(tmp_path: Path) -> None:
    script = tmp_path / "typo.cml"
    script.write_text("S.1=10\n@wiat 1\n")
    done = run_coolmuscle("check", str(script))
    assert done.returncode == 1
    assert f"{script}:2:1: error[script] unknown directive @wiat" in done.stdout
    assert run_coolmuscle("run", str(script)).returncode == 2
