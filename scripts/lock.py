"""Write constraints.txt: the exact version of every package the scripts install.

The package itself asks for ranges (pyproject.toml: a lower bound, the next major
excluded), so that it installs beside other users of numpy or pymodbus.  The versions
CI runs with are pinned here, in one file that scripts/_env.sh installs with
(``pip install -c constraints.txt ...``).  This script writes it from an environment
that passes the tests: every distribution reached from the build requirements, the
dependencies and the extras ``all``, ``test``, ``docs`` and ``accel`` of pyproject.toml
(each requirement's markers evaluated here, its extras followed), at the version
installed in the interpreter that runs it::

    .venv/bin/python scripts/lock.py          # then review and commit constraints.txt

A requirement that is not installed, or installed at a version outside its range, is an
error (the file would pin something the tests never ran with), except one pinned with
``==`` in pyproject.toml itself (the build requirements), which is taken as written
(the build environment has them, not this one).
"""

from __future__ import annotations

import sys
import tomllib
from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
EXTRAS = ("all", "test", "docs", "accel")
HEADER = """\
# The exact versions CI installs (scripts/_env.sh: pip install -c constraints.txt ...).
# pyproject.toml asks for ranges; these are the versions the tests ran with.
# Written by scripts/lock.py from an environment that passes them: do not edit by hand.
"""


def requirements(project: dict[str, object]) -> list[Requirement]:
    """The build requirements, the dependencies and those of :data:`EXTRAS` (with the
    extras they name of the project itself)."""
    build = project["build-system"]["requires"]                      # type: ignore[index]
    meta = project["project"]
    found = [Requirement(r) for r in [*build, *meta["dependencies"]]]  # type: ignore[index]
    extras = meta["optional-dependencies"]                           # type: ignore[index]
    todo, seen = list(EXTRAS), set()
    while todo:
        extra = todo.pop()
        if extra in seen:
            continue
        seen.add(extra)
        for text in extras[extra]:
            req = Requirement(text)
            if canonicalize_name(req.name) == "coolmuscle":
                todo += list(req.extras)
            else:
                found.append(req)
    return found


def closure(roots: list[Requirement]) -> dict[str, str]:
    """Every distribution reached from ``roots``: canonical name -> installed version."""
    pinned: dict[str, str] = {}
    todo = [(req, "") for req in roots]
    done: set[tuple[str, frozenset[str]]] = set()
    while todo:
        req, extra = todo.pop()
        if req.marker is not None and not req.marker.evaluate({"extra": extra}):
            continue
        name = canonicalize_name(req.name)
        key = (name, frozenset(req.extras))
        if key in done:
            continue
        done.add(key)
        exact = [s.version for s in req.specifier if s.operator == "=="]
        try:
            dist = distribution(req.name)
        except PackageNotFoundError:
            dist = None
        if exact and (dist is None or dist.version != exact[0]):
            pinned[name] = exact[0]    # pinned in pyproject.toml itself (the build's)
            continue
        if dist is None:
            sys.exit(f"lock: {req} is not installed here")
        if not req.specifier.contains(dist.version, prereleases=True):
            sys.exit(f"lock: {req.name} {dist.version} is installed, outside {req}")
        pinned[name] = dist.version
        for text in dist.requires or []:
            sub = Requirement(text)
            for wanted in ("", *req.extras):
                todo.append((sub, wanted))
    return pinned


def main() -> None:
    with open(ROOT / "pyproject.toml", "rb") as f:
        project = tomllib.load(f)
    pinned = closure(requirements(project))
    lines = [f"{name}=={version}" for name, version in sorted(pinned.items())]
    (ROOT / "constraints.txt").write_text(HEADER + "\n".join(lines) + "\n", encoding="utf-8")
    print(f"constraints.txt: {len(lines)} packages")


if __name__ == "__main__":
    main()
