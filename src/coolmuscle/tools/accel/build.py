"""Compile again, check or remove the compiled hot modules in place (coolmuscle/_accel.py).

Usage::

    python -m coolmuscle.tools.accel build [--force] [--quiet]
    python -m coolmuscle.tools.accel status
    python -m coolmuscle.tools.accel clean

The package build compiles them (``pip install .``, ``pip install -e .``, a wheel:
``setup.py`` and :mod:`.compiler`).  ``build`` does the same in place, without pip: after
a hot module was edited in an editable install (the sources run until then), it
compiles :data:`coolmuscle._accel.MODULES` beside their sources with the mypy of this
environment (``pip install -e ".[accel]"``; a C compiler and the Python headers are
needed) and writes the build stamp.  It does nothing when the build is current (and
records the times again when sources were only touched).  ``status`` says whether the
compiled modules are current and in use, and why not.  ``clean`` removes them.  Exit
status: 0 compiled or current, 1 not compiled (the sources run), 2 bad usage.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ... import _accel
from . import compiler


def build(force: bool = False, quiet: bool = False) -> int:
    """Compile the modules in place unless the build is current; 0 when compiled."""
    def log(line: str) -> None:
        print(line, file=sys.stderr)

    package = Path(_accel.PACKAGE_DIR)
    try:
        outcome = compiler.build(_accel, package, in_place=True, force=force,
                                 lock=package / ".accel-build.lock", log=log)
    except compiler.CompileError as exc:
        print(f"compiling the hot modules failed: {exc}", file=sys.stderr)
        return 1
    if outcome.compiled and not quiet:
        print("compiled modules are current" if outcome.reason == "current" else outcome.reason)
    return 0 if outcome.compiled else 1


def status() -> int:
    """One line: current or not and why, in use or not; 0 when the build is current."""
    try:
        values = _accel.read_stamp(_accel.PACKAGE_DIR)
    except ValueError as exc:
        print(f"compiled modules: not in use; {exc}")
        return 1
    why = _accel.refusal(values)
    if why is not None:
        print(f"compiled modules: not in use; {why}")
        return 1
    assert values is not None
    used = "in use" if _accel.active() else f"not in use ({_accel.state['reason']})"
    print(f"compiled modules: {used}; {_accel.built(values)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] not in ("build", "status", "clean"):
        print((__doc__ or "").split("Usage::")[1].split("The package")[0].rstrip(),
              file=sys.stderr)
        return 2
    command, flags = args[0], set(args[1:])
    if not flags <= {"--force", "--quiet"}:
        print(f"unknown option {sorted(flags - {'--force', '--quiet'})[0]}", file=sys.stderr)
        return 2
    try:
        if command == "build":
            return build(force="--force" in flags, quiet="--quiet" in flags)
        if command == "clean":
            compiler.clean(_accel, Path(_accel.PACKAGE_DIR))
            return 0
        return status()
    except OSError as exc:            # a read-only install, a full disk
        print(f"coolmuscle.tools.accel {command}: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
