"""Compiled copies of the model's hot modules (mypyc): which copy runs, read from the
build stamp the build wrote, never from the sources.

The servo and load model, the planner, the kernel and the alarm watchers are plain
Python (the code one reads next to the manual).  The package build compiles the
modules of :data:`MODULES` with mypyc (``setup.py``: ``pip install .``, ``pip install
-e .``, a wheel; ``python -m coolmuscle.tools.accel build`` compiles them again in
place; coolmuscle/tools/accel/compiler.py) in mypyc's own layout: each module's
extension beside its source (``sim/kernel.py`` and ``sim/kernel.cpython-311-...so``)
and the code of them all in one shared library (``_hot__mypyc.cpython-311-...so``).
Python's import system prefers an extension module to a source of the same name, so
a compiled module is what ``import`` finds: nothing is patched or hooked.

The build writes the **build stamp** last, the module ``coolmuscle/_build_stamp.py``:
what it compiled (or why it kept the sources), for which interpreter, the files it
wrote and, for a build in place (an editable install, the build tool), the size and
modification time of each hot module's source when it was compiled.  At ``import
coolmuscle``, :func:`choose` imports that stamp (a module: no file is read, no source
hashed) and decides:

* compiled, when the stamp says so, names this interpreter and this module list, and
  (a build in place only) every hot module's source has the size and time recorded:
  the import system finds the extensions, nothing is done;
* the sources otherwise: ``COOLMUSCLE_PURE`` set to anything but ``""`` or ``0``, a
  hot module edited since it was compiled in place (one edited module turns the whole
  set off: compiled modules call each other directly, so a stale one would still run
  inside a fresh one; a stale compiled module never runs), a build cut short, another
  interpreter's build.  Then each folder that holds compiled files gets, in
  ``sys.path_importer_cache`` (the import system's cache of the finder of each
  folder), the finder the import system would make for it without extension modules:
  the sources run.  Nothing outside the package's own folders is touched.

:func:`describe` says which and why (``coolmuscle --version``).  The compiled code is
the same source, so the numbers are the same (tests/test_accel.py and
tests/test_packaging.py run both and compare them byte for byte).

Standard library only and no import of coolmuscle: ``setup.py`` loads this file by
path in a build environment without coolmuscle's dependencies.
"""

from __future__ import annotations

import os
import sys

TYPE_CHECKING = False      # typing.TYPE_CHECKING without importing typing at start
if TYPE_CHECKING:
    from types import ModuleType

#: The modules compiled, leaves of the import graph first; one a line.
MODULES: list[str] = [
    "coolmuscle.sim.memo",
    "coolmuscle.cml.ast",
    "coolmuscle.motor.state.param_table",
    "coolmuscle.motor.motion.expoly",
    "coolmuscle.motor.motion.profile",
    "coolmuscle.motor.motion.planner",
    "coolmuscle.motor.motion.dynamics",
    "coolmuscle.motor.motion.axis",
    "coolmuscle.motor.supervision.alarms",
    "coolmuscle.motor.supervision.thermal",
    "coolmuscle.sim.kernel",
    "coolmuscle.motor.motion.trajectory",
    "coolmuscle.motor.programs.bankexec",
    "coolmuscle.motor.programs.program",
    "coolmuscle.motor.supervision.limits",
    "coolmuscle.device.hostline",
    "coolmuscle.motor.signals.io",
    "coolmuscle.motor.state.memory",
    "coolmuscle.motor.signals.analog",
    "coolmuscle.motor.signals.analog_output",
    "coolmuscle.motor.signals.encoder",
    "coolmuscle.motor.signals.analog_control",
    "coolmuscle.motor.status",
    "coolmuscle.motor.supervision.push",
    "coolmuscle.motor.supervision.faults",
    "coolmuscle.motor.programs.bankcheck",
    "coolmuscle.motor.supervision.sensors",
    "coolmuscle.motor.supervision.origin",
    "coolmuscle.motor.supervision.supervisor",
    "coolmuscle.motor.motor",
    "coolmuscle.chain.bus",
    "coolmuscle.frontends.ethercat.bridge.cia402",
    "coolmuscle.frontends.ethercat.engine.dictionary",
    "coolmuscle.frontends.ethercat.bridge.modes",
    "coolmuscle.frontends.ethercat.bridge.cpio",
    "coolmuscle.frontends.ethercat.bridge.csp",
    "coolmuscle.frontends.ethercat.bridge.homing",
    "coolmuscle.frontends.ethercat.bridge.link",
    "coolmuscle.frontends.ethercat.bridge.cml_mailbox",
    "coolmuscle.frontends.ethercat.bridge.axis",
    "coolmuscle.frontends.ethercat.bridge.drive",
    "coolmuscle.tools.script.record",
]

#: mypyc's group: its shared library is the module ``coolmuscle._hot__mypyc``.
GROUP = "coolmuscle._hot"
#: The build stamp, a module of the package written by the build (file name).
STAMP_FILE = "_build_stamp.py"

#: The package's folder (the folder of this file).
PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))

#: How to compile them again, for the reasons that name it.
REBUILD = "python -m coolmuscle.tools.accel build, or pip install again"

#: Why the compiled modules are (not) in use: ``active`` and ``reason``.
state: dict[str, object] = {"active": False, "reason": "not chosen yet (coolmuscle not imported)"}


def pure_requested() -> bool:
    """``COOLMUSCLE_PURE`` is set to anything but ``""`` or ``0``: run the sources."""
    return os.environ.get("COOLMUSCLE_PURE", "") not in ("", "0")


def source_relpath(module: str) -> str:
    """The source of one of :data:`MODULES`, relative to the package folder, with ``/``
    (``coolmuscle.sim.kernel`` -> ``sim/kernel.py``)."""
    return "/".join(module.split(".")[1:]) + ".py"


def source_stats(package_dir: str | None = None) -> dict[str, list[int]]:
    """Size and modification time (ns) of each hot module's source in ``package_dir``
    (default :data:`PACKAGE_DIR`): what a build in place records and :func:`choose`
    compares (``os.stat``, nothing is read)."""
    package_dir = PACKAGE_DIR if package_dir is None else package_dir
    stats: dict[str, list[int]] = {}
    for module in MODULES:
        rel = source_relpath(module)
        st = os.stat(os.path.join(package_dir, *rel.split("/")))
        stats[rel] = [st.st_size, st.st_mtime_ns]
    return stats


def source_digest(package_dir: str | None = None) -> str:
    """BLAKE2b over the names and sources of :data:`MODULES`: what the build tool
    compares to tell an edit from a file only touched (never computed at import)."""
    from hashlib import blake2b

    package_dir = PACKAGE_DIR if package_dir is None else package_dir

    h = blake2b(digest_size=32)
    for module in MODULES:
        rel = source_relpath(module)
        h.update(module.encode() + b"\0")
        with open(os.path.join(package_dir, *rel.split("/")), "rb") as f:
            h.update(f.read())
        h.update(b"\0")
    return h.hexdigest()


#: What a build stamp holds (coolmuscle/tools/accel/compiler.py writes it).
STAMP_NAMES = ("COMPILED", "REASON", "MYPYC", "CACHE_TAG", "MODULES", "FILES", "DIGEST",
               "SOURCES")


def stamp_values(stamp: ModuleType | dict[str, object]) -> dict[str, object]:
    """The stamp's values by name (from the imported module or from :func:`read_stamp`)."""
    found = stamp if isinstance(stamp, dict) else vars(stamp)
    return {name: found.get(name) for name in STAMP_NAMES}


def refusal(values: dict[str, object] | None, package_dir: str | None = None) -> str | None:
    """Why the compiled modules of the stamp ``values`` of the package folder
    ``package_dir`` (default :data:`PACKAGE_DIR`) must not run (``None``: they may).

    ``COOLMUSCLE_PURE`` is not looked at here (the build tool asks whether a build is
    current whatever the environment says)."""
    package_dir = PACKAGE_DIR if package_dir is None else package_dir
    if values is None:
        return f"not compiled; {REBUILD}"
    if values["COMPILED"] is not True:
        return str(values["REASON"] or "not compiled")
    files, sources, modules = values["FILES"], values["SOURCES"], values["MODULES"]
    if not isinstance(files, list) or not isinstance(modules, list) or not (
            sources is None or isinstance(sources, dict)):
        return f"build stamp malformed; {REBUILD}"
    if values["CACHE_TAG"] != sys.implementation.cache_tag:
        return f"compiled for {values['CACHE_TAG']}, this is {sys.implementation.cache_tag}"
    if modules != MODULES:
        return f"compiled for another module list; {REBUILD}"
    if sources is None:                  # a wheel: its sources are the ones it was built from
        return None
    for rel, recorded in sources.items():
        try:
            st = os.stat(os.path.join(package_dir, *str(rel).split("/")))
        except OSError:
            return f"{rel} is missing; {REBUILD}"
        if [st.st_size, st.st_mtime_ns] != recorded:
            return f"a hot module changed since it was compiled ({rel}); {REBUILD}"
    for rel in files:
        if not os.path.isfile(os.path.join(package_dir, *str(rel).split("/"))):
            return f"a compiled file is missing ({rel}); {REBUILD}"
    return None


def built(values: dict[str, object]) -> str:
    """What a current stamp says of its build, in words."""
    where = "in place from the current sources" if values["SOURCES"] else "with the package"
    return f"built {where} by mypyc {values['MYPYC']}"


def choose(package_dir: str) -> None:
    """At ``import coolmuscle`` (``package_dir`` is its ``__path__[0]``): the compiled
    modules when the build stamp says they are current, else the sources (module
    docstring).  Reads no file besides importing the stamp; when compiled, changes
    nothing."""
    values: dict[str, object] | None = None
    reason: str | None = None
    try:
        values = stamp_values(__import__(f"coolmuscle.{STAMP_FILE[:-3]}", fromlist=["_"]))
    except ModuleNotFoundError as exc:
        if exc.name != f"coolmuscle.{STAMP_FILE[:-3]}":
            reason = f"build stamp unreadable: {exc}"
    except Exception as exc:             # a damaged stamp is no build
        reason = f"build stamp unreadable: {exc}"
    if pure_requested():
        reason = "COOLMUSCLE_PURE is set"
    elif reason is None:
        reason = refusal(values, package_dir)
    if reason is None:
        assert values is not None
        state.update(active=True, reason=built(values))
        return
    state.update(active=False, reason=reason)
    files = values["FILES"] if values is not None else None
    if isinstance(files, list) and files:
        sources_first(package_dir, [str(f) for f in files])


def sources_first(package_dir: str, files: list[str]) -> None:
    """The folders holding ``files`` (compiled files, relative to ``package_dir``) get
    the finder the import system would give them, without extension modules: the
    sources beside them are imported instead.  Only these folders of the package are
    touched (their entries of ``sys.path_importer_cache``)."""
    from importlib.machinery import (
        BYTECODE_SUFFIXES,
        SOURCE_SUFFIXES,
        FileFinder,
        SourceFileLoader,
        SourcelessFileLoader,
    )

    for folder in sorted({os.path.dirname(f) for f in files} - {""}):
        # the key the import system uses: the parent package's __path__ entry joined
        # with the sub-package's name, as coolmuscle.__path__[0] + "/motor/motion"
        path = os.path.join(package_dir, *folder.split("/"))
        sys.path_importer_cache[path] = FileFinder(
            path, (SourceFileLoader, SOURCE_SUFFIXES), (SourcelessFileLoader, BYTECODE_SUFFIXES))


def read_stamp(package_dir: str) -> dict[str, object] | None:
    """The stamp of the package folder ``package_dir`` (a build directory, the source
    tree) by executing its file, or ``None`` when there is none; ``ValueError`` when it
    does not run.  For the build and the build tool, not for import."""
    path = os.path.join(package_dir, STAMP_FILE)
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        return None
    namespace: dict[str, object] = {}
    try:
        exec(compile(text, path, "exec"), namespace)
    except Exception as exc:             # a damaged stamp is no build
        raise ValueError(f"build stamp unreadable: {exc}") from exc
    return stamp_values(namespace)


def active() -> bool:
    """True when the compiled modules are the ones imported."""
    return bool(state["active"])


def describe() -> str:
    """One line for ``coolmuscle --version``: compiled, or the sources and why."""
    if active():
        return f"hot modules: compiled ({len(MODULES)} modules {state['reason']})"
    return f"hot modules: sources ({state['reason']})"
