"""CI output of the commands: ``check --format sarif|github``, ``--junit`` of ``check``,
``run`` and ``compare``; the SARIF log validates against the OASIS 2.1.0 schema.

Every finding and every failing expectation must land on its file and line: the
human form of ``check`` (``path:line:col: ...``) is the reference the others agree with.
"""

from __future__ import annotations

import copy
import json
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import jsonschema
import pytest

from cli_support import cli
from coolmuscle.tools.ci.github import annotation
from coolmuscle.tools.ci.junit import Case, Suite, write_junit
from schema_support import validate_sarif

ROOT = Path(__file__).resolve().parents[1]
BAD = ROOT / "tests" / "data" / "check"
SESSION = ROOT / "examples" / "twin" / "session.cml"
#: Findings of both severities, and a clean file.
FILES = [BAD / "missing-bank.cml", BAD / "register-unset.cml", BAD / "syntax.cml",
         ROOT / "examples" / "2.2-program-bank.cml"]


def findings(capsys: pytest.CaptureFixture[str], *paths: Path) -> list[tuple[str, int, int,
                                                                             str, str]]:
    """(path, line, column, severity, rule) of every finding, from the human form."""
    _code, out, _err = cli(capsys, "check", *map(str, paths))
    found = []
    for line in out.splitlines():
        head, _, rest = line.partition(": ")
        if rest.startswith(("error[", "warning[")):
            path, number, column = head.rsplit(":", 2)
            severity, rule = rest.split("]", 1)[0].split("[")
            found.append((path, int(number), int(column), severity, rule))
    return found


def test_sarif_validates_and_puts_each_finding_on_its_line(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Relative paths stay relative URIs (code scanning resolves them in the checkout)."""
    monkeypatch.chdir(ROOT)
    relative = [p.relative_to(ROOT) for p in FILES]
    expected = findings(capsys, *relative)
    assert {f[3] for f in expected} == {"error", "warning"}
    code, out, _err = cli(capsys, "check", "--format", "sarif", *map(str, relative))
    assert code == 1
    log = json.loads(out)
    validate_sarif(log)
    run = log["runs"][0]
    rules = run["tool"]["driver"]["rules"]
    got = []
    for result in run["results"]:
        place = result["locations"][0]["physicalLocation"]
        assert rules[result["ruleIndex"]]["id"] == result["ruleId"]
        assert run["artifacts"][place["artifactLocation"]["index"]]["location"]["uri"] \
            == place["artifactLocation"]["uri"]
        got.append((place["artifactLocation"]["uri"], place["region"]["startLine"],
                    place["region"]["startColumn"], result["level"], result["ruleId"]))
    assert got == expected
    _code, out, _err = cli(capsys, "check", "--format", "sarif", str(FILES[0]))
    log = json.loads(out)
    validate_sarif(log)
    assert log["runs"][0]["artifacts"][0]["location"]["uri"] == FILES[0].as_uri()


def test_the_sarif_schema_bites() -> None:
    """A log the schema refuses: a result without its message, a region at line 0."""
    good = {"version": "2.1.0", "runs": [{"tool": {"driver": {"name": "x"}}, "results": [
        {"ruleId": "syntax", "message": {"text": "m"}, "locations": [{"physicalLocation": {
            "artifactLocation": {"uri": "a.cml"}, "region": {"startLine": 1}}}]}]}]}
    validate_sarif(good)
    for path, value in ((("results", 0, "message"), None),
                        (("results", 0, "locations", 0, "physicalLocation", "region",
                          "startLine"), 0)):
        bad: Any = copy.deepcopy(good)
        node = bad["runs"][0]
        for key in path[:-1]:
            node = node[key]
        if value is None:
            del node[path[-1]]
        else:
            node[path[-1]] = value
        with pytest.raises(jsonschema.ValidationError):
            validate_sarif(bad)


def test_github_annotations_name_file_line_and_column(
        capsys: pytest.CaptureFixture[str]) -> None:
    expected = findings(capsys, *FILES)
    code, out, _err = cli(capsys, "check", "--format", "github", *map(str, FILES))
    assert code == 1
    commands = [line for line in out.splitlines() if line.startswith("::")]
    assert len(commands) == len(expected)
    for line, (path, number, column, severity, rule) in zip(commands, expected):
        assert line.startswith(f"::{severity} file={path},line={number},col={column},"
                               f"title=coolmuscle check%3A {rule}::")
    assert out.splitlines()[-1] == f"{FILES[-1]}: 0 errors, 0 warnings; 1 bank (cm2); motor 1: " \
        "5/500 commands"                                     # the summaries follow


def test_workflow_commands_escape_what_would_end_them() -> None:
    assert annotation("error", "50% of\nline, here: yes", file="a b,c:d.cml", line=3,
                      col=1, title="t: x") == (
        "::error file=a b%2Cc%3Ad.cml,line=3,col=1,title=t%3A x::50%25 of%0Aline, here: yes")
    assert annotation("notice", "plain") == "::notice::plain"


def junit(path: Path) -> list[ET.Element]:
    root = ET.parse(path).getroot()
    assert root.tag == "testsuites"
    return list(root.iter("testcase"))


def test_check_junit_has_a_case_per_finding_with_its_file_and_line(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    expected = findings(capsys, *FILES)
    out = tmp_path / "check.xml"
    assert cli(capsys, "check", "--junit", str(out), *map(str, FILES))[0] == 1
    cases = junit(out)
    found = [c for c in cases if c.get("name") != "check"]
    assert [(c.get("file"), int(c.get("line", 0))) for c in found] == \
        [(p, n) for p, n, *_ in expected]
    assert [c.find("failure") is not None for c in found] == \
        [severity == "error" for *_, severity, _rule in expected]
    clean = [c for c in cases if c.get("name") == "check"]
    assert [c.get("file") for c in clean] == [str(FILES[-1])]
    strict = tmp_path / "strict.xml"
    cli(capsys, "check", "--strict", "--junit", str(strict), *map(str, FILES))
    assert all(c.find("failure") is not None for c in junit(strict) if c.get("name") != "check")


def test_check_junit_to_a_missing_folder_is_bad_usage(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, _out, err = cli(capsys, "check", "--junit", str(tmp_path / "no" / "x.xml"),
                          str(FILES[-1]))
    assert code == 2 and "cannot write --junit" in err


SCRIPT = ("K23.1=17\n<< K23.1=17\\r\\n\n?96.1\n<< ?96.1\\r\\n\n<< Px.1=0\\r\\n\n"
          "P1.1=100\n<< P1.1=100\\r\\n\n?96.1\n<< ?96.1\\r\\n\n<< Px.1=7\\r\\n\n")


def exit_status(main: Any, *args: str) -> int:
    try:
        main(list(args))
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


@pytest.mark.parametrize("until", ["1", "1e0"], ids=["plain-run", "typer-run"])
def test_run_junit_names_the_line_of_the_failed_expectation(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, until: str) -> None:
    """Both ways into ``run`` (plain arguments skip typer; ``1e0`` is not plain)."""
    from coolmuscle.tools.cli.entry import main
    script = tmp_path / "move.cml"
    script.write_text(SCRIPT)
    out = tmp_path / "run.xml"
    assert exit_status(main, "run", str(script), "--check", "--until", until,
                       "--junit", str(out)) == 1
    [case] = junit(out)
    failure = case.find("failure")
    assert failure is not None and failure.get("type") == "mismatch"
    assert (case.get("file"), case.get("line"), case.get("name")) == (str(script), "10",
                                                                      "move.cml")
    assert failure.get("message", "").startswith(f'{script}:10: expected "Px.1=7')
    script.write_text(SCRIPT.replace("Px.1=7", "Px.1=0"))       # no move yet: passes
    assert exit_status(main, "run", str(script), "--check", "--until", until,
                       "--junit", str(out)) == 0
    [case] = junit(out)
    assert list(case) and case.find("failure") is None and case.get("line") is None


def test_compare_junit_has_a_case_per_line_the_real_motor_said(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    from coolmuscle.tools.twin.compare import compare_session
    out = tmp_path / "compare.xml"
    code, text, _err = cli(capsys, "compare", str(SESSION), "--junit", str(out))
    report = compare_session(SESSION)
    cases = junit(out)
    assert len(cases) == len(report.verdicts)
    assert code == (0 if report.ok else 1) and f"wrote {out}" in text
    failing = [c for c in cases if c.find("failure") is not None]
    assert len(failing) == len(report.differences)
    lines = SESSION.read_text().splitlines()
    for case, verdict in zip(cases, report.verdicts):
        assert case.get("file") == str(SESSION)
        if verdict.real is not None:
            number = int(case.get("line", "0"))
            assert number == verdict.real.line_no
            assert verdict.real.text in lines[number - 1]     # the line of the capture


def test_the_junit_writer_counts_and_escapes(tmp_path: Path) -> None:
    path = write_junit(tmp_path / "j.xml", [Suite("s", [
        Case("a", "c", 0.5), Case("b <&>", "c", 1.25, "failure", 'says "x"', "t",
                                  file="f.cml", line=4),
        Case("c", "c", None, "error", "boom"), Case("d", "c", None, "skipped", "later")])])
    root = ET.parse(path).getroot()
    suite = root.find("testsuite")
    assert suite is not None
    assert [root.get(k) for k in ("tests", "failures", "errors")] == ["4", "1", "1"]
    assert [suite.get(k) for k in ("failures", "errors", "skipped", "time")] == \
        ["1", "1", "1", "1.750"]
    failed = suite.findall("testcase")[1]
    assert (failed.get("name"), failed.get("file"), failed.get("line")) == ("b <&>", "f.cml",
                                                                            "4")
    assert failed.find("failure").text == 'says "x"'        # type: ignore[union-attr]
