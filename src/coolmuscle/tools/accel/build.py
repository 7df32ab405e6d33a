"""Compile again, check or remove the compiled hot modules in place (coolmuscle/_accel.py).

Usage::

    python -m coolmuscle.tools.accel build [--force] [--quiet]
    python -m coolmuscle.tools.accel status
    python -m coolmuscle.tools.accel clean

The package build compiles them (``pip install .``, ``pip install -e .``, a wheel:
``setup.py`` and :mod:`.compiler`).  ``build`` does the same in place, without pip: after
a hot module was edited in an editable install (the sources run until then), it
compiles :data:`coolmuscle._accel.MODULES` into ``coolmuscle/_compiled/`` with the mypy
of this environment (``pip install -e ".[accel]"``; a C compiler and the Python headers
are needed).  It does nothing when the build is current.  ``status`` says whether the
compiled modules are in use, and why not.  Exit status: 0 compiled or current, 1 not
compiled (the sources run), 2 bad usage.
"""

from __future__ import annotations

import sys

from ... import _accel
from . import compiler


def build(force: bool = False, quiet: bool = False) -> int:
    """Compile the modules in place unless the build is current; 0 when compiled."""
    def log(line: str) -> None:
        print(line, file=sys.stderr)

    try:
        outcome = compiler.build(_accel, _accel.BUILD_DIR, force=force,
                                 lock=_accel.PACKAGE_DIR / ".accel-build.lock", log=log)
    except compiler.CompileError as exc:
        print(f"compiling the hot modules failed: {exc}", file=sys.stderr)
        return 1
    if outcome.compiled and not quiet:
        print("compiled modules are current" if outcome.reason == "current" else outcome.reason)
    return 0 if outcome.compiled else 1


def status() -> int:
    """One line: in use or not, and why; 0 when the build is current."""
    files, reason = _accel.read_manifest()
    used = "in use" if _accel.active() else "not in use"
    print(f"compiled modules: {used}; {reason}")
    return 0 if files is not None else 1


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
            compiler.clean(_accel.BUILD_DIR)
            return 0
        return status()
    except OSError as exc:            # a read-only install, a full disk
        print(f"coolmuscle.tools.accel {command}: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
