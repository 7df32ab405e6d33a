"""JUnit XML, the test report every CI system reads (Jenkins, GitLab, GitHub actions that
publish test results, Azure DevOps).

One ``<testsuites>`` holding ``<testsuite>`` elements, each with its ``<testcase>``
elements; a case that failed holds a ``<failure>`` (an expectation not met), an
``<error>`` (the run itself broke) or a ``<skipped>``.  A case may name the file and the
line it is about (``file`` and ``line`` attributes, as pytest's xunit1 report writes
them), so a reviewer lands on the line of a script, a capture or a CML file.

``batch`` (docs/batch.md), ``run --check``, ``compare`` and ``check`` all write through
:func:`write_junit`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

__all__ = ["Case", "Suite", "junit_tree", "write_junit", "path_problem"]

Outcome = Literal["passed", "failure", "error", "skipped"]


@dataclass(frozen=True)
class Case:
    """One test case: ``message`` is the short text of a failure, error or skip, ``text``
    its long form (the message when not given); ``output`` goes to ``<system-out>``."""

    name: str
    classname: str
    time: float | None = 0.0
    outcome: Outcome = "passed"
    message: str = ""
    kind: str = ""
    text: str | None = None
    file: str | None = None
    line: int | None = None
    output: str | None = None


@dataclass(frozen=True)
class Suite:
    """One ``<testsuite>``: its cases, and its time (the cases' sum when not given)."""

    name: str
    cases: Sequence[Case] = field(default_factory=tuple)
    time: float | None = None


def _count(cases: Sequence[Case], outcome: Outcome) -> int:
    return sum(case.outcome == outcome for case in cases)


def _case(parent: ET.Element, case: Case) -> None:
    attrs = {"classname": case.classname, "name": case.name,
             "time": "0" if case.time is None else f"{case.time:.3f}"}
    if case.file is not None:
        attrs["file"] = case.file
    if case.line is not None:
        attrs["line"] = str(case.line)
    element = ET.SubElement(parent, "testcase", attrs)
    if case.outcome == "skipped":
        ET.SubElement(element, "skipped", {"message": case.message})
    elif case.outcome in ("failure", "error"):
        node = ET.SubElement(element, case.outcome, {"message": case.message,
                                                     "type": case.kind or case.outcome})
        node.text = case.message if case.text is None else case.text
    if case.output:
        ET.SubElement(element, "system-out").text = case.output


def junit_tree(suites: Sequence[Suite]) -> ET.ElementTree[ET.Element | None]:
    """The document: totals on ``<testsuites>`` and on each ``<testsuite>``."""
    root = ET.Element("testsuites")
    totals = {"tests": 0, "failures": 0, "errors": 0}
    for suite in suites:
        cases = list(suite.cases)
        time = suite.time if suite.time is not None else sum(c.time or 0.0 for c in cases)
        element = ET.SubElement(root, "testsuite", {
            "name": suite.name, "tests": str(len(cases)),
            "failures": str(_count(cases, "failure")), "errors": str(_count(cases, "error")),
            "skipped": str(_count(cases, "skipped")), "time": f"{time:.3f}"})
        for case in cases:
            _case(element, case)
        totals["tests"] += len(cases)
        totals["failures"] += _count(cases, "failure")
        totals["errors"] += _count(cases, "error")
    for key, value in totals.items():
        root.set(key, str(value))
    tree = ET.ElementTree(root)
    ET.indent(tree)
    return tree


def write_junit(path: Path, suites: Sequence[Suite]) -> Path:
    """Write the JUnit XML of ``suites`` to ``path`` (UTF-8, with the declaration)."""
    path = path.expanduser()
    junit_tree(suites).write(path, encoding="utf-8", xml_declaration=True)
    return path


def path_problem(path: Path) -> str | None:
    """Why ``path`` cannot take the report (checked before a run), or ``None``."""
    path = path.expanduser()
    if not path.parent.is_dir():
        return f"directory {path.parent} does not exist"
    if path.is_dir():
        return f"{path} is a directory"
    return None
