"""Compile the hot modules (:data:`coolmuscle._accel.MODULES`) with mypyc into a build
directory, or say there why the sources run.

Used by the package build (``setup.py``'s ``build_accel`` step: ``pip install .``,
``pip install -e .``, ``python -m build``) and by ``python -m coolmuscle.tools.accel
build``.  Standard library only, and no import of coolmuscle: ``setup.py`` loads this
file and ``_accel.py`` by path in a build environment that has mypy and setuptools but
none of coolmuscle's dependencies, and hands ``_accel`` in (:class:`Sources`).

``COOLMUSCLE_COMPILE`` in the build's environment chooses:

* unset, empty or ``auto``: compile when mypyc, a C compiler and the Python headers
  are there; otherwise the build succeeds and the sources run;
* ``0``: never compile (the sources run);
* ``1``: compile or fail the build (a release, a test that must get the compiled
  modules).

Unless it fails (``1``), a build leaves a manifest in the build directory, written
last: the compiled files and the digest of their sources, or ``{"compiled": false,
"reason": ...}``.  A failed rebuild never removes a current build.
"""

from __future__ import annotations

import fcntl
import json
import os
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from dataclasses import dataclass
from importlib.util import find_spec
from pathlib import Path
from typing import Callable, Protocol, Sequence

ENV = "COOLMUSCLE_COMPILE"

#: The setup script run in a child interpreter (mypyc's build is a setuptools build).
#: ``--follow-imports=silent``: mypy still reads the modules the hot ones import (for
#: their types) but reports errors only in the compiled ones; a build environment has
#: none of coolmuscle's dependencies (pyserial, numpy ...), so their importers would
#: otherwise fail the type check that a full environment passes.
_SETUP = """
import sys
from setuptools import setup
from mypyc.build import mypycify
paths, out, tmp = sys.argv[1].split(","), sys.argv[2], sys.argv[3]
options = ["--follow-imports=silent", "--cache-dir=" + tmp + "/mypy-cache"]
setup(name="coolmuscle-accel", packages=[],
      ext_modules=mypycify(options + paths, opt_level="3", target_dir=tmp,
                           group_name="coolmuscle_accel"),
      script_args=["build_ext", "--build-lib", out, "--build-temp", tmp])
"""


class Sources(Protocol):
    """What the build needs of :mod:`coolmuscle._accel` (the module satisfies it)."""

    MODULES: tuple[str, ...]
    PACKAGE_DIR: Path
    MANIFEST_NAME: str

    def source_path(self, module: str) -> Path: ...

    def source_digest(self, modules: Sequence[str] = ...) -> str: ...

    def read_manifest(self, build_dir: Path | None = None
                      ) -> tuple[dict[str, Path] | None, str]: ...


class CompileError(Exception):
    """The modules could not be compiled; the message says why in a few words."""


@dataclass(frozen=True)
class Outcome:
    """What a build did: ``compiled`` (the directory holds current compiled modules)
    and ``reason`` in words."""

    compiled: bool
    reason: str


def setting() -> str:
    """``auto``, ``0`` or ``1`` from ``COOLMUSCLE_COMPILE``; ``CompileError`` otherwise."""
    value = os.environ.get(ENV, "").strip().lower() or "auto"
    if value not in ("auto", "0", "1"):
        raise CompileError(f"{ENV} must be 0, 1 or auto, not {value!r}")
    return value


def compiler_command() -> str:
    """The C compiler setuptools will call: ``$CC``, else the interpreter's own."""
    return os.environ.get("CC") or str(sysconfig.get_config_var("CC") or "cc")


def missing() -> str | None:
    """Why compiling cannot even start here (no mypyc, no C compiler, no Python headers),
    or ``None``.  Cheap: nothing is run."""
    if find_spec("mypyc") is None:
        return "no mypy (mypyc) in the build environment"
    words = shlex.split(compiler_command())
    if not words or shutil.which(words[0]) is None:
        name = words[0] if words else "cc"
        return f"no C compiler ({name} not found)"
    include = Path(sysconfig.get_paths()["include"])
    if not (include / "Python.h").is_file():
        version = "%d.%d" % sys.version_info[:2]
        return f"no Python headers ({include}/Python.h; Debian: python{version}-dev)"
    return None


def will_compile() -> bool:
    """True when a build here would try to compile (for the wheel's platform tag)."""
    try:
        return setting() != "0" and missing() is None
    except CompileError:
        return False


def build(accel: Sources, dest: Path, *, force: bool = False, lock: Path | None = None,
          log: Callable[[str], None] = print) -> Outcome:
    """Compile the modules into ``dest`` unless it is current (or ``force``).

    ``lock``: a file whose lock the builds of one directory take in turn (a second one
    waits, then finds the build current).  With ``COOLMUSCLE_COMPILE=1`` a build that
    cannot compile raises :class:`CompileError`, and so does a forced rebuild of a current
    build (which stays); otherwise a build that cannot compile says why in the manifest
    and in its :class:`Outcome`, and the sources run."""
    if lock is None:
        return _build(accel, dest, force, log)
    lock.parent.mkdir(parents=True, exist_ok=True)
    with open(lock, "ab") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        try:
            return _build(accel, dest, force, log)
        finally:
            fcntl.flock(held, fcntl.LOCK_UN)


def _build(accel: Sources, dest: Path, force: bool, log: Callable[[str], None]) -> Outcome:
    choice = setting()
    current = accel.read_manifest(dest)[0] is not None
    if choice == "0":
        return _keep_sources(accel, dest, f"{ENV}=0")
    if current and not force:
        return Outcome(True, "current")
    try:
        why = missing()
        if why is not None:
            raise CompileError(why)
        _compile(accel, dest, log)
    except CompileError as exc:
        if choice == "1" or current:      # required, or a forced rebuild: keep what is there
            raise
        log(f"the hot modules are not compiled ({exc}); the sources run")
        return _keep_sources(accel, dest, str(exc))
    return Outcome(True, f"compiled {len(accel.MODULES)} modules into {dest}")


def _keep_sources(accel: Sources, dest: Path, reason: str) -> Outcome:
    clean(dest)
    _write_manifest(accel, dest, {"compiled": False, "reason": reason})
    return Outcome(False, reason)


def _compile(accel: Sources, dest: Path, log: Callable[[str], None]) -> None:
    """Run mypyc in a child interpreter, then replace ``dest`` with its output.  A failure
    logs the end of mypyc's output and raises with its last line."""
    src = accel.PACKAGE_DIR.parent
    paths = [str(accel.source_path(m).relative_to(src)) for m in accel.MODULES]
    digest = accel.source_digest()
    with tempfile.TemporaryDirectory(prefix="coolmuscle-accel-") as work:
        out, tmp = Path(work) / "out", Path(work) / "tmp"
        setup_py = Path(work) / "setup_accel.py"
        setup_py.write_text(_SETUP, encoding="utf-8")
        env = dict(os.environ, COOLMUSCLE_PURE="1")
        proc = subprocess.run(
            [sys.executable, str(setup_py), ",".join(paths), str(out), str(tmp)],
            cwd=src, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
            log("\n".join(lines[-15:]))
            last = lines[-1].strip()[:200] if lines else f"exit status {proc.returncode}"
            raise CompileError(f"mypyc or the C compiler failed: {last}")
        files = {_module_name(so.relative_to(out)): str(so.relative_to(out))
                 for so in sorted(out.rglob("*.so"))}
        absent = [m for m in accel.MODULES if m not in files]
        if absent:
            raise CompileError(f"no compiled output for {', '.join(absent)}")
        clean(dest)
        for rel in files.values():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(out / rel, dest / rel)
    _write_manifest(accel, dest, {
        "compiled": True, "cache_tag": sys.implementation.cache_tag,
        "modules": list(accel.MODULES), "digest": digest, "files": files,
        "mypyc": _mypy_version()})


def _module_name(rel: Path) -> str:
    """``coolmuscle/sim/kernel.cpython-311-x86_64-linux-gnu.so`` -> ``coolmuscle.sim.kernel``."""
    return ".".join(rel.parts[:-1] + (rel.name.split(".")[0],))


def _mypy_version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("mypy")
    except PackageNotFoundError:
        return "?"


def _write_manifest(accel: Sources, dest: Path, record: dict[str, object]) -> None:
    """Write the manifest through a temporary file, so a build cut short has none."""
    dest.mkdir(parents=True, exist_ok=True)
    part = dest / (accel.MANIFEST_NAME + ".part")
    part.write_text(json.dumps(record, indent=1), encoding="utf-8")
    os.replace(part, dest / accel.MANIFEST_NAME)


def clean(dest: Path) -> None:
    """Remove a build directory (the sources run)."""
    shutil.rmtree(dest, ignore_errors=True)
