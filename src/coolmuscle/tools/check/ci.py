"""``coolmuscle check`` for CI: SARIF 2.1.0, GitHub annotations and JUnit XML.

* :func:`to_sarif` - the SARIF log code scanning reads (OASIS SARIF 2.1.0: one run, the
  rules as ``tool.driver.rules``, each finding a ``result`` with its file, line and
  column; the motor's error number in the result's ``properties``);
* :func:`github_lines` - one ``::error``/``::warning`` workflow command per finding
  (:mod:`coolmuscle.tools.ci.github`), so a pull request shows it on the CML line;
* :func:`junit_suites` - a ``<testsuite>`` per file, a ``<testcase>`` per finding
  (a ``<failure>`` for an error, and for a warning under ``--strict``) with its file
  and line, and one passing case for a file without findings.
"""

from __future__ import annotations

import urllib.parse
from pathlib import Path
from typing import Any

from ... import __version__
from ..ci.github import annotation
from ..ci.junit import Case, Suite
from .report import RULES, CheckReport, Diagnostic

__all__ = ["to_sarif", "github_lines", "junit_suites", "SARIF_SCHEMA"]

SARIF_SCHEMA = "https://json.schemastore.org/sarif-2.1.0.json"
TOOL = "coolmuscle check"


def _uri(path: str) -> str:
    """A file's URI reference: relative paths stay relative (to the checkout, as code
    scanning wants them), absolute ones become ``file://`` URIs."""
    candidate = Path(path)
    if candidate.is_absolute():
        return candidate.as_uri()
    return urllib.parse.quote(candidate.as_posix())


def _failing(diagnostic: Diagnostic, strict: bool) -> bool:
    return diagnostic.severity == "error" or strict


def _rules() -> list[dict[str, Any]]:
    return [{"id": rule, "name": rule,
             "defaultConfiguration": {"level": severity},
             "properties": {} if number is None else {"motorError": f"error{number:02d}"}}
            for rule, (severity, number) in RULES.items()]


def to_sarif(reports: list[CheckReport], *, strict: bool = False) -> dict[str, Any]:
    """The SARIF log of ``reports`` (a warning is an error under ``--strict``)."""
    index = {rule: i for i, rule in enumerate(RULES)}
    artifacts = [{"location": {"uri": _uri(r.path)}} for r in reports]
    results = []
    for number, report in enumerate(reports):
        for d in report.diagnostics:
            result: dict[str, Any] = {
                "ruleId": d.rule, "ruleIndex": index[d.rule],
                "level": "error" if _failing(d, strict) else "warning",
                "message": {"text": d.message},
                "locations": [{"physicalLocation": {
                    "artifactLocation": {"uri": _uri(report.path), "index": number},
                    "region": {"startLine": d.line, "startColumn": d.column}}}]}
            if d.motor_error is not None:
                result["properties"] = {"motorError": f"error{d.motor_error:02d}",
                                        "firmware": report.firmware}
            results.append(result)
    driver = {"name": TOOL, "version": __version__, "rules": _rules()}
    return {"$schema": SARIF_SCHEMA, "version": "2.1.0",
            "runs": [{"tool": {"driver": driver}, "artifacts": artifacts,
                      "results": results}]}


def _text(d: Diagnostic) -> str:
    number = f" (error{d.motor_error:02d})" if d.motor_error is not None else ""
    return f"{d.message}{number}"


def github_lines(reports: list[CheckReport], *, strict: bool = False) -> list[str]:
    """One workflow command per finding, in file order."""
    return [annotation("error" if _failing(d, strict) else "warning", _text(d),
                       file=report.path, line=d.line, col=d.column,
                       title=f"coolmuscle check: {d.rule}")
            for report in reports for d in report.diagnostics]


def junit_suites(reports: list[CheckReport], *, strict: bool = False) -> list[Suite]:
    """A suite per file: a case per finding, or one passing case for a clean file."""
    suites = []
    for report in reports:
        cases = []
        for d in report.diagnostics:
            name = f"line {d.line}:{d.column} {d.rule}"
            where = f"{report.path}:{d.line}:{d.column}"
            if _failing(d, strict):
                cases.append(Case(name, report.path, None, "failure", _text(d), d.rule,
                                  text=d.format(report.path), file=report.path, line=d.line))
            else:
                cases.append(Case(name, report.path, None, file=report.path, line=d.line,
                                  output=f"{where}: warning[{d.rule}] {_text(d)}"))
        if not cases:
            cases.append(Case("check", report.path, None, file=report.path))
        suites.append(Suite(f"coolmuscle check {report.path}", cases))
    return suites
