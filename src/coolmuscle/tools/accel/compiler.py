"""Compile the hot modules (:data:`coolmuscle._accel.MODULES`) with mypyc into a package
folder, and write its build stamp: what was compiled, or why the sources run.

Used by the package build (``setup.py``'s ``build_accel`` step: ``pip install .``,
``pip install -e .``, ``python -m build``) and by ``python -m coolmuscle.tools.accel
build``.  Standard library only, and no import of coolmuscle: ``setup.py`` loads this
file and ``_accel.py`` by path in a build environment that has mypy and setuptools but
none of coolmuscle's dependencies, and hands ``_accel`` in (:class:`Sources`).

The output is mypyc's own layout: each module's extension beside its source
(``sim/kernel.cpython-311-x86_64-linux-gnu.so`` beside ``sim/kernel.py``) and their
shared library (``_hot__mypyc.cpython-311-...so``), in a wheel's build folder or in
place in the source tree.  ``COOLMUSCLE_COMPILE`` in the build's environment chooses:

* unset, empty or ``auto``: compile when mypyc, a C compiler and the Python headers
  are there; otherwise the build succeeds and the sources run;
* ``0``: never compile (the sources run);
* ``1``: compile or fail the build (a release, a test that must get the compiled
  modules).

Unless it fails (``1``), a build leaves the stamp (``_build_stamp.py``, a module
:func:`coolmuscle._accel.choose` imports), written through a temporary file: while the
compiled files are replaced it says "cut short" and names the old and the new ones
(their folders then run the sources), then what was built.  A failed rebuild never
removes a current build.
"""

from __future__ import annotations

import fcntl
import os
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from importlib.machinery import EXTENSION_SUFFIXES
from importlib.util import cache_from_source, find_spec
from pathlib import Path
from typing import Protocol

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
paths, out, tmp, group = sys.argv[1].split(","), sys.argv[2], sys.argv[3], sys.argv[4]
options = ["--follow-imports=silent", "--cache-dir=" + tmp + "/mypy-cache"]
setup(name="coolmuscle-accel", packages=[],
      ext_modules=mypycify(options + paths, opt_level="3", target_dir=tmp,
                           group_name=group),
      script_args=["build_ext", "--build-lib", out, "--build-temp", tmp])
"""


class Sources(Protocol):
    """What the build needs of :mod:`coolmuscle._accel` (the module satisfies it)."""

    MODULES: list[str]
    GROUP: str
    STAMP_FILE: str
    PACKAGE_DIR: str
    REBUILD: str

    def source_relpath(self, module: str) -> str: ...

    def source_stats(self, package_dir: str | None = ...) -> dict[str, list[int]]: ...

    def source_digest(self, package_dir: str | None = ...) -> str: ...

    def read_stamp(self, package_dir: str) -> dict[str, object] | None: ...

    def refusal(self, values: dict[str, object] | None,
                package_dir: str | None = ...) -> str | None: ...


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


def build(accel: Sources, dest: Path, *, in_place: bool, force: bool = False,
          lock: Path | None = None, log: Callable[[str], None] = print) -> Outcome:
    """Compile the modules into the package folder ``dest`` unless it is current (or
    ``force``).

    ``in_place``: ``dest`` is the source tree itself (an editable install, the build
    tool): the stamp records each hot source's size and time, and a build that is
    current is left as it is (one whose sources were only touched, same bytes, gets its
    times recorded again instead of a compile).  Otherwise ``dest`` is a wheel's build
    folder and is always compiled.  ``lock``: a file whose lock the builds of one
    folder take in turn (a second one waits, then finds the build current).  With
    ``COOLMUSCLE_COMPILE=1`` a build that cannot compile raises :class:`CompileError`,
    and so does a forced rebuild of a current build (which stays); otherwise a build
    that cannot compile says why in the stamp and in its :class:`Outcome`, and the
    sources run."""
    if lock is None:
        return _build(accel, dest, in_place, force, log)
    lock.parent.mkdir(parents=True, exist_ok=True)
    with open(lock, "ab") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        try:
            return _build(accel, dest, in_place, force, log)
        finally:
            fcntl.flock(held, fcntl.LOCK_UN)


def current_stamp(accel: Sources, dest: Path) -> dict[str, object] | None:
    """The stamp of ``dest`` when it says its compiled modules may run, else ``None``."""
    try:
        values = accel.read_stamp(str(dest))
    except ValueError:
        return None
    return values if accel.refusal(values, str(dest)) is None else None


def _touched_only(accel: Sources, dest: Path) -> dict[str, object] | None:
    """A stamp refused only because sources were touched (same bytes, new times): the
    stamp, else ``None``."""
    try:
        values = accel.read_stamp(str(dest))
    except ValueError:
        return None
    if values is None or values["COMPILED"] is not True or values["SOURCES"] is None:
        return None
    again = dict(values, SOURCES=None)          # every other check as before
    if accel.refusal(again, str(dest)) is not None:
        return None
    files = values["FILES"]
    if not isinstance(files, list) or not all((dest / str(f)).is_file() for f in files):
        return None
    try:
        return values if values["DIGEST"] == accel.source_digest(str(dest)) else None
    except OSError:
        return None


def _build(accel: Sources, dest: Path, in_place: bool, force: bool,
           log: Callable[[str], None]) -> Outcome:
    choice = setting()
    current = in_place and current_stamp(accel, dest) is not None
    if choice == "0":
        return _keep_sources(accel, dest, f"{ENV}=0")
    if current and not force:
        return Outcome(True, "current")
    touched = _touched_only(accel, dest) if in_place and not force else None
    if touched is not None:
        _write_stamp(accel, dest, dict(touched, SOURCES=accel.source_stats(str(dest))))
        return Outcome(True, "current (sources touched, not changed: their times recorded)")
    try:
        why = missing()
        if why is not None:
            raise CompileError(why)
        _compile(accel, dest, in_place, log)
    except CompileError as exc:
        if choice == "1" or current:      # required, or a forced rebuild: keep what is there
            raise
        log(f"the hot modules are not compiled ({exc}); the sources run")
        return _keep_sources(accel, dest, str(exc))
    return Outcome(True, f"compiled {len(accel.MODULES)} modules into {dest}")


def _keep_sources(accel: Sources, dest: Path, reason: str) -> Outcome:
    clean(accel, dest)
    _write_stamp(accel, dest, {"COMPILED": False,
                               "REASON": f"not compiled at install time: {reason}",
                               "FILES": []})
    return Outcome(False, reason)


def _compile(accel: Sources, dest: Path, in_place: bool, log: Callable[[str], None]) -> None:
    """Run mypyc in a child interpreter, then put its output in ``dest``: the stamp says
    "cut short" (naming the old and the new files) while the files are replaced, then
    what was built.  A failure logs the end of mypyc's output and raises with its last
    line."""
    package = Path(accel.PACKAGE_DIR)
    src = package.parent
    paths = [str((package / accel.source_relpath(m)).relative_to(src)) for m in accel.MODULES]
    digest = accel.source_digest()             # before compiling: an edit meanwhile is stale
    stats = accel.source_stats() if in_place else None
    with tempfile.TemporaryDirectory(prefix="coolmuscle-accel-") as work:
        out, tmp = Path(work) / "out", Path(work) / "tmp"
        setup_py = Path(work) / "setup_accel.py"
        setup_py.write_text(_SETUP, encoding="utf-8")
        env = dict(os.environ, COOLMUSCLE_PURE="1")
        proc = subprocess.run(
            [sys.executable, str(setup_py), ",".join(paths), str(out), str(tmp), accel.GROUP],
            cwd=src, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
            log("\n".join(lines[-15:]))
            last = lines[-1].strip()[:200] if lines else f"exit status {proc.returncode}"
            raise CompileError(f"mypyc or the C compiler failed: {last}")
        built = out / package.name
        files = sorted(p.relative_to(built).as_posix() for p in _extensions(built))
        modules = {_module_name(f) for f in files}
        absent = [m for m in accel.MODULES
                  if accel.source_relpath(m)[:-3].replace("/", ".") not in modules]
        if absent:
            raise CompileError(f"no compiled output for {', '.join(absent)}")
        old = _stamp_files(accel, dest)
        _write_stamp(accel, dest, {
            "COMPILED": False, "FILES": sorted(set(old) | set(files)),
            "REASON": f"a build of the compiled modules was cut short; {accel.REBUILD}"})
        _remove_extensions(dest)
        for rel in files:
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(built / rel, dest / rel)
    _write_stamp(accel, dest, {
        "COMPILED": True, "REASON": "", "MYPYC": _mypy_version(),
        "CACHE_TAG": sys.implementation.cache_tag, "MODULES": list(accel.MODULES),
        "FILES": files, "DIGEST": digest, "SOURCES": stats})


def _module_name(rel: str) -> str:
    """``sim/kernel.cpython-311-x86_64-linux-gnu.so`` -> ``sim.kernel``."""
    folder, _, name = rel.rpartition("/")
    return ".".join(filter(None, (folder.replace("/", "."), name.split(".")[0])))


def _mypy_version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("mypy")
    except PackageNotFoundError:
        return "?"


def _extensions(folder: Path) -> list[Path]:
    """The extension-module files under ``folder`` (any of this interpreter's suffixes)."""
    suffixes = tuple(EXTENSION_SUFFIXES)
    return [p for p in folder.rglob("*") if p.name.endswith(suffixes) and p.is_file()]


def _stamp_files(accel: Sources, dest: Path) -> list[str]:
    """The compiled files the stamp of ``dest`` names, and any other extension file there."""
    try:
        values = accel.read_stamp(str(dest))
    except ValueError:
        values = None
    named = values["FILES"] if values is not None else None
    found = [p.relative_to(dest).as_posix() for p in _extensions(dest)] if dest.is_dir() else []
    return sorted(set(found) | {str(f) for f in named} if isinstance(named, list) else set(found))


def stamp_text(values: dict[str, object]) -> str:
    """The stamp module's source: one ``NAME = value`` a line, lists one item a line."""
    lines = ['"""The build stamp of the compiled hot modules, written by the build',
             "(coolmuscle/tools/accel/compiler.py) and imported by coolmuscle/_accel.py:",
             'which copy of the hot modules runs.  Generated: do not edit."""', ""]
    for name in ("COMPILED", "REASON", "MYPYC", "CACHE_TAG", "MODULES", "FILES", "DIGEST",
                 "SOURCES"):
        value = values.get(name)
        if name == "SOURCES":
            lines.append("#: In place: (size, mtime_ns) of each hot source when compiled; "
                         "None in a wheel.")
            if isinstance(value, dict):
                lines.append("SOURCES: dict[str, list[int]] | None = {")
                lines += [f"    {k!r}: {list(v)!r}," for k, v in sorted(value.items())]
                lines.append("}")
            else:
                lines.append("SOURCES: dict[str, list[int]] | None = None")
        elif isinstance(value, list):
            lines.append(f"{name}: list[str] = [")
            lines += [f"    {item!r}," for item in value]
            lines.append("]")
        else:
            kind = "bool" if name == "COMPILED" else "str"
            lines.append(f"{name}: {kind} = {(value if value is not None else '')!r}")
    return "\n".join(lines) + "\n"


def _write_stamp(accel: Sources, dest: Path, values: dict[str, object]) -> None:
    """Write the stamp through a temporary file (a build cut short leaves the previous
    one whole) and drop its byte code (a stamp rewritten within the same second with
    the same size would otherwise be read from a stale ``.pyc``)."""
    dest.mkdir(parents=True, exist_ok=True)
    path = dest / accel.STAMP_FILE
    part = dest / (accel.STAMP_FILE + ".part")
    part.write_text(stamp_text(values), encoding="utf-8")
    os.replace(part, path)
    _drop_byte_code(path)


def _drop_byte_code(path: Path) -> None:
    cached = Path(cache_from_source(str(path)))
    for pyc in cached.parent.glob(path.stem + ".*.pyc"):
        pyc.unlink(missing_ok=True)


def _remove_extensions(dest: Path) -> None:
    if dest.is_dir():
        for found in _extensions(dest):
            found.unlink()
    shutil.rmtree(dest / "_compiled", ignore_errors=True)    # the layout before the stamp


def clean(accel: Sources, dest: Path) -> None:
    """Remove the compiled modules and the stamp of the package folder ``dest`` (the
    sources run): the stamp first says "cut short" naming the files, so that a clean
    cut short still keeps them out."""
    files = _stamp_files(accel, dest)
    if files:
        _write_stamp(accel, dest, {
            "COMPILED": False, "FILES": files,
            "REASON": f"removing the compiled modules was cut short; {accel.REBUILD}"})
        _remove_extensions(dest)
    stamp = dest / accel.STAMP_FILE
    if stamp.exists():
        stamp.unlink()
        _drop_byte_code(stamp)
