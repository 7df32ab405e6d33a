"""Build, check or remove the compiled hot modules (coolmuscle/_accel.py).

Usage::

    python -m coolmuscle.tools.accel build [--force] [--quiet]
    python -m coolmuscle.tools.accel status
    python -m coolmuscle.tools.accel clean

``build`` compiles :data:`coolmuscle._accel.MODULES` with mypyc (``pip install -e
".[accel]"`` brings mypy and setuptools; a C compiler and the Python headers are
needed) into ``src/coolmuscle/_compiled/`` and writes its manifest last, so a build cut
short is never used.  It does nothing when the build is current.  Exit status: 0 built
or current, 1 the build failed (the sources keep running), 2 bad usage.
"""

from __future__ import annotations

import fcntl
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from ... import _accel

#: The setup script run in a child interpreter (mypyc's build is a setuptools build).
_SETUP = """
import sys
from setuptools import setup
from mypyc.build import mypycify
paths, out, tmp = sys.argv[1].split(","), sys.argv[2], sys.argv[3]
setup(name="coolmuscle-accel", packages=[],
      ext_modules=mypycify(paths, opt_level="3", target_dir=tmp, group_name="coolmuscle_accel"),
      script_args=["build_ext", "--build-lib", out, "--build-temp", tmp])
"""


def _current() -> bool:
    files, _ = _accel._read_manifest()
    return files is not None


def build(force: bool = False, quiet: bool = False) -> int:
    """Compile the modules unless the build is current; 0 on success.  Builds take
    turns (a lock file beside the package): a second one waits, then finds it current."""
    _accel.PACKAGE_DIR.joinpath(".accel-build.lock").touch(exist_ok=True)
    with open(_accel.PACKAGE_DIR / ".accel-build.lock", "rb") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            return _build(force, quiet)
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _build(force: bool, quiet: bool) -> int:
    if not force and _current():
        if not quiet:
            print("compiled modules are current")
        return 0
    if importlib.util.find_spec("mypyc") is None:
        print("compiling the hot modules needs mypy (pip install -e '.[accel]'); "
              "the sources run as they are", file=sys.stderr)
        return 1
    src = _accel.PACKAGE_DIR.parent
    paths = [str(_accel.source_path(m).relative_to(src)) for m in _accel.MODULES]
    digest = _accel.source_digest()
    clean()
    with tempfile.TemporaryDirectory(prefix="coolmuscle-accel-") as work:
        out, tmp = Path(work) / "out", Path(work) / "tmp"
        setup_py = Path(work) / "setup_accel.py"
        setup_py.write_text(_SETUP, encoding="utf-8")
        env = dict(os.environ, COOLMUSCLE_PURE="1")
        proc = subprocess.run(
            [sys.executable, str(setup_py), ",".join(paths), str(out), str(tmp)],
            cwd=src, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            tail = "\n".join((proc.stdout + proc.stderr).splitlines()[-15:])
            print(f"compiling the hot modules failed; the sources run as they are.\n{tail}",
                  file=sys.stderr)
            return 1
        built = sorted(p for p in out.rglob("*.so"))
        files: dict[str, str] = {}
        _accel.BUILD_DIR.mkdir(parents=True, exist_ok=True)
        for so in built:
            rel = so.relative_to(out)
            name = ".".join(rel.parts[:-1] + (rel.name.split(".")[0],))
            dest = _accel.BUILD_DIR / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(so, dest)
            files[name] = str(rel)
    missing = [m for m in _accel.MODULES if m not in files]
    if missing:
        print(f"compiling the hot modules failed: no output for {', '.join(missing)}",
              file=sys.stderr)
        clean()
        return 1
    manifest = {"cache_tag": sys.implementation.cache_tag, "modules": list(_accel.MODULES),
                "digest": digest, "files": files}
    part = _accel.MANIFEST.with_suffix(".part")
    part.write_text(json.dumps(manifest, indent=1), encoding="utf-8")
    os.replace(part, _accel.MANIFEST)
    if not quiet:
        print(f"compiled {len(_accel.MODULES)} modules into {_accel.BUILD_DIR}")
    return 0


def clean() -> None:
    """Remove the compiled modules (the sources run)."""
    shutil.rmtree(_accel.BUILD_DIR, ignore_errors=True)


def status() -> int:
    files, reason = _accel._read_manifest()
    used = "in use" if _accel.active() else "not in use"
    print(f"compiled modules: {used}; {reason}")
    return 0 if files is not None else 1


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] not in ("build", "status", "clean"):
        print(__doc__.split("Usage::")[1].split("``build``")[0].rstrip(), file=sys.stderr)
        return 2
    command, flags = args[0], set(args[1:])
    if not flags <= {"--force", "--quiet"}:
        print(f"unknown option {sorted(flags - {'--force', '--quiet'})[0]}", file=sys.stderr)
        return 2
    try:
        if command == "build":
            return build(force="--force" in flags, quiet="--quiet" in flags)
        if command == "clean":
            clean()
            return 0
        return status()
    except OSError as exc:            # a read-only install, a full disk
        print(f"coolmuscle.tools.accel {command}: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
