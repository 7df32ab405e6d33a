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

import json
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
#:
#: It says what it is doing on lines that start with :data:`PROGRESS` (the parent
#: passes them on): the mypyc step, then each C file as the compiler finishes it, and
#: every :data:`HEARTBEAT` seconds of silence what it is still doing.  The C files are
#: compiled ``jobs`` at a time (distutils compiles an extension's files one by one, and
#: setuptools' ``--parallel`` only runs whole extensions side by side).
_SETUP = r"""
import json, os, sys, threading, time
from concurrent.futures import ThreadPoolExecutor
from setuptools import setup
from setuptools.command.build_ext import build_ext
from mypyc.build import mypycify

paths, out, tmp = sys.argv[1].split(","), sys.argv[2], sys.argv[3]
plan = json.loads(sys.argv[4])
jobs = max(1, int(plan["jobs"]))
START = time.monotonic()
lock = threading.Lock()
state = {"doing": "starting", "said": START}

def say(text, doing=None):
    with lock:
        state["said"] = time.monotonic()
        state["doing"] = doing or text
        # one write: the compiler threads' own lines must not land inside it
        sys.stdout.write("%s[%3.0f s] %s\n" % (plan["prefix"], state["said"] - START, text))
        sys.stdout.flush()

def heartbeat():
    while True:
        time.sleep(1.0)
        with lock:
            quiet, doing = time.monotonic() - state["said"], state["doing"]
        if quiet >= plan["heartbeat"]:
            say("still " + doing, doing)

threading.Thread(target=heartbeat, daemon=True).start()
groups = plan["groups"]
separate = [(g["paths"], g["name"]) for g in groups] if groups else bool(plan["separate"])
say("mypyc: checking the types of %d modules and writing their C code" % len(paths),
    "checking types and writing C code (mypyc)")
extensions = mypycify(
    ["--follow-imports=silent", "--cache-dir=" + tmp + "/mypy-cache"] + paths,
    opt_level=plan["opt_level"], multi_file=plan["multi_file"], separate=separate,
    target_dir=tmp, group_name=None if (groups or plan["separate"]) else plan["group"])
# a group named in a package ("coolmuscle._hot") has its header in that package's folder,
# where mypyc's files of one module each (multi_file) do not look
for ext in extensions:
    ext.include_dirs.append(os.path.join(tmp, *plan["group"].split(".")[:-1]))
total = sum(len(ext.sources) for ext in extensions)
done = [0]
say("mypyc: done; compiling %d C files, %d at a time, at -O%s"
    % (total, jobs, plan["opt_level"]), "compiling C files")
slots = threading.BoundedSemaphore(jobs)

class BuildExt(build_ext):
    def build_extensions(self):
        flags = plan["flags"]              # compiled and linked with (link_time_flags)
        for ext in self.extensions:
            ext.extra_compile_args = list(ext.extra_compile_args or []) + flags
            ext.extra_link_args = list(ext.extra_link_args or []) + flags
        whole = self.compiler.compile

        def one(source, kwargs):
            with slots:
                objects = whole([source], **kwargs)
            with lock:
                done[0] += 1
                count = done[0]
            say("C compiler: %d/%d %s" % (count, total, os.path.basename(source)),
                "compiling C files (%d/%d done)" % (count, total) if count < total
                else "linking" + (" (optimising the library as a whole)" if any(
                    f.startswith("-flto") for f in flags) else ""))
            return objects

        def compile(sources, **kwargs):
            with ThreadPoolExecutor(max(1, min(jobs, len(sources)))) as pool:
                return [o for objs in pool.map(lambda s: one(s, kwargs), sources) for o in objs]

        self.compiler.compile = compile
        biggest = sorted(self.extensions, key=lambda e: -len(e.sources))
        with ThreadPoolExecutor(jobs) as pool:
            list(pool.map(self.build_extension, biggest))

setup(name="coolmuscle-accel", packages=[], ext_modules=extensions,
      cmdclass={"build_ext": BuildExt},
      script_args=["-q", "build_ext", "--build-lib", out, "--build-temp", tmp])
say("built %d extension modules" % len(extensions))
"""

#: The lines of the child's output that say what it is doing (passed to ``log``).
PROGRESS = "coolmuscle-accel: "
#: Seconds of silence after which the child says what it is still doing.
HEARTBEAT = 10.0


@dataclass(frozen=True)
class Plan:
    """How the modules are compiled (docs/performance.md "Compiled hot modules": each
    lever measured).  ``groups``: ``None`` for one shared library (:data:`Sources.GROUP`),
    else ``(library, module prefixes)`` pairs; a module goes to the first whose prefix
    it starts with (the last group should take ``""``).  ``separate``: every module its
    own library.  ``jobs``: C files compiled at a time (0: the CPUs this process may
    use).  ``link_time``: optimise each library as a whole when it is linked, its own
    symbols hidden, where the C compiler takes it (:func:`link_time_flags`)."""

    opt_level: str = "3"
    multi_file: bool = False
    link_time: bool = True
    groups: tuple[tuple[str, tuple[str, ...]], ...] | None = None
    separate: bool = False
    jobs: int = 0

    def job_count(self) -> int:
        if self.jobs > 0:
            return self.jobs
        try:
            return max(1, len(os.sched_getaffinity(0)))
        except AttributeError:                 # not Linux
            return max(1, os.cpu_count() or 1)


#: Link-time optimisation with a library's own symbols hidden (only its module init
#: functions exported): calls between the modules are then direct, and the linker may
#: inline across them.  The first set the C compiler takes: GCC's spelling (``auto``:
#: the link's optimisation runs on every CPU), Clang's; else hidden symbols alone.
LINK_TIME: tuple[tuple[str, ...], ...] = (
    ("-fvisibility=hidden", "-flto=auto"),
    ("-fvisibility=hidden", "-flto=thin"),
    ("-fvisibility=hidden",),
)


def link_time_flags(work: Path) -> tuple[str, ...]:
    """The first set of :data:`LINK_TIME` with which the C compiler (:func:`compiler_command`)
    compiles and links a small shared library in the folder ``work``; ``()`` when it
    takes none, or on Windows (MSVC spells them otherwise)."""
    if sys.platform == "win32":
        return ()
    source = work / "link_time_probe.c"
    source.write_text("int probe(int x) { return x + 1; }\n", encoding="utf-8")
    for flags in LINK_TIME:
        command = [*shlex.split(compiler_command()), *flags, "-fPIC", "-shared",
                   str(source), "-o", str(work / "link_time_probe.so")]
        try:
            done = subprocess.run(command, capture_output=True, timeout=120)
        except (OSError, subprocess.SubprocessError):
            return ()
        if done.returncode == 0:
            return flags
    return ()


#: The plan of the package build: a C file a module, compiled side by side on every CPU,
#: at -O3.  One C file for all 37 modules took 129 s of CPU, one compiler process after
#: another; a file a module 70 s, at the same speed of the compiled code (callgrind's
#: instructions within 1 %).  -O2 took as long; -O1 52 s, for up to 4 % more
#: instructions.  Optimised as a whole when linked (``link_time``), 86 s, for 6-10 % fewer
#: instructions and 12 % less CPU time in the bridge's cycle (bench/bench_compile.py;
#: docs/performance.md "Compiled hot modules").
PLAN = Plan(multi_file=True)


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
          lock: Path | None = None, log: Callable[[str], None] = print,
          plan: Plan = PLAN) -> Outcome:
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
    sources run.  ``log`` gets what the compile is doing, a line at a time, as it goes
    (``plan``: how it compiles)."""
    if lock is None:
        return _build(accel, dest, in_place, force, log, plan)
    lock.parent.mkdir(parents=True, exist_ok=True)
    with open(lock, "ab") as held:
        _lock_file(held.fileno())
        return _build(accel, dest, in_place, force, log, plan)   # closing the file unlocks


def _lock_file(fd: int) -> None:
    """Wait for the exclusive lock of the open file ``fd``: ``flock`` (POSIX), else
    ``msvcrt.locking`` on its first byte (Windows), else none.  Imported here, not at
    the top: ``setup.py`` loads this file on every system."""
    if sys.platform == "win32":
        import msvcrt

        os.lseek(fd, 0, os.SEEK_SET)
        while True:
            try:
                msvcrt.locking(fd, msvcrt.LK_LOCK, 1)     # retries for 10 s, then raises
                return
            except OSError:
                continue
    try:
        import fcntl
    except ImportError:
        return
    fcntl.flock(fd, fcntl.LOCK_EX)


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
           log: Callable[[str], None], plan: Plan) -> Outcome:
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
        _compile(accel, dest, in_place, log, plan)
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


def _plan_json(accel: Sources, plan: Plan, paths: dict[str, str],
               flags: tuple[str, ...] = ()) -> str:
    """The child's settings: ``plan`` with its groups as lists of paths, and the flags
    every C file is compiled and linked with."""
    groups: list[dict[str, object]] | None = None
    if plan.groups is not None:
        members: dict[str, list[str]] = {name: [] for name, _ in plan.groups}
        for module, path in paths.items():
            short = module.removeprefix("coolmuscle.")
            name = next((n for n, prefixes in plan.groups
                         if any(short.startswith(p) for p in prefixes)), None)
            if name is None:
                raise CompileError(f"no group of the plan takes {module}")
            members[name].append(path)
        groups = [{"name": name, "paths": found} for name, found in members.items() if found]
    return json.dumps({"opt_level": plan.opt_level, "multi_file": plan.multi_file,
                       "flags": list(flags),
                       "separate": plan.separate, "groups": groups, "group": accel.GROUP,
                       "jobs": plan.job_count(), "prefix": PROGRESS, "heartbeat": HEARTBEAT})


def _run_child(command: list[str], cwd: Path, log: Callable[[str], None]) -> list[str]:
    """Run the child, passing its progress lines to ``log`` as they come; its whole
    output, or :class:`CompileError` with the end of it."""
    env = dict(os.environ, COOLMUSCLE_PURE="1", PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(command, cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, errors="replace")
    lines: list[str] = []
    assert proc.stdout is not None
    with proc:
        for line in proc.stdout:
            line = line.rstrip("\n")
            if PROGRESS in line:          # (another thread's output may come before it)
                log(line.split(PROGRESS, 1)[1])
            elif line.strip():
                lines.append(line)
    if proc.returncode != 0:
        log("\n".join(lines[-15:]))
        last = lines[-1].strip()[:200] if lines else f"exit status {proc.returncode}"
        raise CompileError(f"mypyc or the C compiler failed: {last}")
    return lines


def _compile(accel: Sources, dest: Path, in_place: bool, log: Callable[[str], None],
             plan: Plan) -> None:
    """Run mypyc in a child interpreter, then put its output in ``dest``: the stamp says
    "cut short" (naming the old and the new files) while the files are replaced, then
    what was built.  A failure logs the end of mypyc's output and raises with its last
    line."""
    package = Path(accel.PACKAGE_DIR)
    src = package.parent
    paths = {m: str((package / accel.source_relpath(m)).relative_to(src))
             for m in accel.MODULES}
    digest = accel.source_digest()             # before compiling: an edit meanwhile is stale
    stats = accel.source_stats() if in_place else None
    with tempfile.TemporaryDirectory(prefix="coolmuscle-accel-") as work:
        out, tmp = Path(work) / "out", Path(work) / "tmp"
        setup_py = Path(work) / "setup_accel.py"
        setup_py.write_text(_SETUP, encoding="utf-8")
        flags: tuple[str, ...] = ()
        if plan.link_time:
            flags = link_time_flags(Path(work))
            log("C compiler flags for the whole library: "
                + (" ".join(flags) or "none (the compiler takes none of them)"))
        _run_child([sys.executable, str(setup_py), ",".join(paths.values()), str(out),
                    str(tmp), _plan_json(accel, plan, paths, flags)], src, log)
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
