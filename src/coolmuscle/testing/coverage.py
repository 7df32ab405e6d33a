"""Bank coverage: which lines of which program and ladder banks ran during a test run.

``pytest --cm-coverage`` (docs/testing-your-project.md "Bank coverage"): every chain the
plug-in builds (``cm_chain``) is observed through the device API
(:meth:`~coolmuscle.chain.daisy.Chain.observe_bank_lines`): a program bank line counts
once each time it starts, a ladder line once each scan that reaches it.  The banks a
test loaded from a file (:func:`.banks.load_bank_file`) count by their file's lines; a
line that never ran is listed with 0.  At the end: a terminal table per file (banks,
lines, lines run, the lines that never ran) and, with ``--cm-coverage-xml PATH``, a
Cobertura XML (:mod:`coolmuscle.tools.ci.cobertura`): a class per file, a method per
bank, so a CI coverage viewer shows the CML file with its lines marked.

Under pytest-xdist each worker collects its own; :meth:`BankCoverage.data` and
:meth:`BankCoverage.merge` carry it to the controller.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

from .banks import BankFile

__all__ = ["FileCoverage", "BankCoverage", "line_ranges"]

#: The name under which banks that did not come from a file are listed.
NO_FILE = "(banks typed in, not loaded from a file)"


@dataclass
class FileCoverage:
    """One CML file: hits per bank line, and which lines each bank holds."""

    path: str
    hits: dict[int, int] = field(default_factory=dict)
    banks: dict[str, list[int]] = field(default_factory=dict)

    @property
    def run(self) -> int:
        return sum(1 for h in self.hits.values() if h)

    def missing(self) -> list[int]:
        return sorted(n for n, h in self.hits.items() if not h)


def line_ranges(numbers: Iterable[int]) -> str:
    """``3-5, 9`` for [3, 4, 5, 9]."""
    out: list[str] = []
    run: list[int] = []
    for n in sorted(numbers):
        if run and n == run[-1] + 1:
            run.append(n)
            continue
        if run:
            out.append(f"{run[0]}-{run[-1]}" if len(run) > 1 else str(run[0]))
        run = [n]
    if run:
        out.append(f"{run[0]}-{run[-1]}" if len(run) > 1 else str(run[0]))
    return ", ".join(out)


class BankCoverage:
    """The bank lines of a whole test run."""

    def __init__(self) -> None:
        self.files: dict[str, FileCoverage] = {}

    def _file(self, path: str) -> FileCoverage:
        if path not in self.files:
            self.files[path] = FileCoverage(path)
        return self.files[path]

    def add_bank_file(self, loaded: BankFile) -> None:
        """Every bank line of a loaded file is there to be run (0 until it is)."""
        cover = self._file(loaded.path)
        for bank in loaded.banks.values():
            lines = sorted(set(bank.lines))
            cover.banks[bank.label] = sorted(set(cover.banks.get(bank.label, [])) | set(lines))
            for number in lines:
                cover.hits.setdefault(number, 0)

    def add_hits(self, path: str, label: str, hits: Mapping[int, int]) -> None:
        """Hits of the lines of bank ``label`` of ``path`` (line -> times run)."""
        cover = self._file(path)
        known = set(cover.banks.get(label, []))
        cover.banks[label] = sorted(known | set(hits))
        for number, count in hits.items():
            cover.hits[number] = cover.hits.get(number, 0) + count

    # -- xdist ----------------------------------------------------------------------
    def data(self) -> dict[str, Any]:
        """What a worker hands the controller (JSON)."""
        return {path: {"hits": {str(n): h for n, h in c.hits.items()}, "banks": c.banks}
                for path, c in self.files.items()}

    def merge(self, data: Mapping[str, Any]) -> None:
        for path, entry in data.items():
            cover = self._file(path)
            for label, lines in entry["banks"].items():
                cover.banks[label] = sorted(set(cover.banks.get(label, [])) | set(lines))
            for number, count in entry["hits"].items():
                cover.hits[int(number)] = cover.hits.get(int(number), 0) + int(count)

    # -- reports --------------------------------------------------------------------
    def table(self) -> list[str]:
        """The terminal table: a row per file, a total, the lines that never ran."""
        rows = [("file", "banks", "lines", "run", "cover", "never ran")]
        files = sorted(self.files.values(), key=lambda c: (c.path == NO_FILE, c.path))
        for c in files:
            rows.append((c.path, str(len(c.banks)), str(len(c.hits)), str(c.run),
                         _percent(c.run, len(c.hits)), line_ranges(c.missing())))
        lines = sum(len(c.hits) for c in files)
        run = sum(c.run for c in files)
        rows.append(("TOTAL", str(sum(len(c.banks) for c in files)), str(lines), str(run),
                     _percent(run, lines), ""))
        widths = [max(len(r[i]) for r in rows) for i in range(5)]
        out = []
        for index, row in enumerate(rows):
            cells = [row[0].ljust(widths[0])] + [row[i].rjust(widths[i]) for i in range(1, 5)]
            out.append("  ".join(cells + [row[5]]).rstrip())
            if index in (0, len(rows) - 2):
                out.append("-" * len(out[0]))
        return out

    def write_xml(self, path: Path, root: Path, version: str) -> Path:
        """Cobertura XML; files are named relative to ``root`` (the ``<source>``)."""
        from ..tools.ci.cobertura import Method, Package, SourceFile, write_cobertura
        packages: dict[str, list[SourceFile]] = {}
        for cover in sorted(self.files.values(), key=lambda c: c.path):
            if cover.path == NO_FILE:
                continue
            name = _relative(cover.path, root)
            methods = [Method(label, {n: cover.hits.get(n, 0) for n in lines})
                       for label, lines in sorted(cover.banks.items())]
            folder = str(PurePosixPath(name).parent)
            packages.setdefault(folder, []).append(
                SourceFile(PurePosixPath(name).name, name, dict(cover.hits), methods))
        return write_cobertura(path, [Package(name, files) for name, files in
                                      sorted(packages.items())], [str(root)],
                               timestamp=int(time.time() * 1000), version=version)


def _percent(run: int, lines: int) -> str:
    return f"{100 * run / lines:.0f}%" if lines else "-"


def _relative(path: str, root: Path) -> str:
    candidate = Path(path)
    if candidate.is_absolute():
        try:
            return candidate.relative_to(root).as_posix()
        except ValueError:
            return candidate.as_posix()
    return PurePosixPath(candidate.as_posix()).as_posix()
