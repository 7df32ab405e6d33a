"""Cobertura coverage XML (coverage-04.dtd), the report CI coverage viewers read (Jenkins'
Coverage plug-in, GitLab's coverage visualisation, Azure DevOps, Codecov).

``<coverage>`` holds ``<sources>`` and ``<packages>``; a package holds classes (here a
source file each: ``filename`` relative to a source), a class its methods (here named
parts of the file) and its ``<lines>``, each ``<line number= hits=>``.  Rates are
covered / valid lines; there are no branches (``branch-rate`` 0 of 0 is written as 1, as
coverage.py does).  The DOCTYPE names the DTD, which the suite validates against
(tests/data/schemas/cobertura-coverage-04.dtd).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["Method", "SourceFile", "Package", "cobertura_text", "write_cobertura"]

DOCTYPE = ('<!DOCTYPE coverage SYSTEM '
           '"http://cobertura.sourceforge.net/xml/coverage-04.dtd">')


@dataclass(frozen=True)
class Method:
    """A named part of a file and its lines (line number -> hits)."""

    name: str
    lines: Mapping[int, int]
    signature: str = ""


@dataclass(frozen=True)
class SourceFile:
    """A file: its name, its path relative to a source, its lines and its parts."""

    name: str
    filename: str
    lines: Mapping[int, int]
    methods: Sequence[Method] = field(default_factory=tuple)


@dataclass(frozen=True)
class Package:
    name: str
    files: Sequence[SourceFile]


def _rate(lines: Mapping[Any, int]) -> str:
    return f"{sum(1 for h in lines.values() if h) / len(lines):.4f}" if lines else "1"


def _lines(parent: ET.Element, lines: Mapping[int, int]) -> None:
    node = ET.SubElement(parent, "lines")
    for number in sorted(lines):
        ET.SubElement(node, "line", {"number": str(number), "hits": str(lines[number]),
                                     "branch": "false"})


def _all_lines(packages: Sequence[Package]) -> dict[tuple[str, int], int]:
    return {(f.filename, n): h for p in packages for f in p.files for n, h in f.lines.items()}


def cobertura_text(packages: Sequence[Package], sources: Sequence[str], *,
                   timestamp: int, version: str) -> str:
    """The document as text (``timestamp`` in ms since the epoch, as Cobertura writes)."""
    everything = _all_lines(packages)
    covered = sum(1 for h in everything.values() if h)
    root = ET.Element("coverage", {
        "line-rate": _rate(everything), "branch-rate": "1",
        "lines-covered": str(covered), "lines-valid": str(len(everything)),
        "branches-covered": "0", "branches-valid": "0", "complexity": "0",
        "version": version, "timestamp": str(timestamp)})
    source_list = ET.SubElement(root, "sources")
    for folder in sources:
        ET.SubElement(source_list, "source").text = folder
    package_list = ET.SubElement(root, "packages")
    for package in packages:
        lines = {(f.filename, n): h for f in package.files for n, h in f.lines.items()}
        node = ET.SubElement(package_list, "package", {
            "name": package.name, "line-rate": _rate(lines), "branch-rate": "1",
            "complexity": "0"})
        classes = ET.SubElement(node, "classes")
        for source in package.files:
            cls = ET.SubElement(classes, "class", {
                "name": source.name, "filename": source.filename,
                "line-rate": _rate(source.lines), "branch-rate": "1", "complexity": "0"})
            methods = ET.SubElement(cls, "methods")
            for method in source.methods:
                element = ET.SubElement(methods, "method", {
                    "name": method.name, "signature": method.signature,
                    "line-rate": _rate(method.lines), "branch-rate": "1", "complexity": "0"})
                _lines(element, method.lines)
            _lines(cls, source.lines)
    ET.indent(root)
    return ("<?xml version=\"1.0\" ?>\n" + DOCTYPE + "\n"
            + ET.tostring(root, encoding="unicode") + "\n")


def write_cobertura(path: Path, packages: Sequence[Package], sources: Sequence[str], *,
                    timestamp: int, version: str) -> Path:
    """Write :func:`cobertura_text` to ``path``."""
    path = path.expanduser()
    path.write_text(cobertura_text(packages, sources, timestamp=timestamp, version=version),
                    encoding="utf-8")
    return path
