"""Compiled copies of the model's hot modules (mypyc), used only when they are current.

The servo and load model, the planner, the kernel and the alarm watchers are plain
Python (the code one reads next to the manual).  The package build compiles the
modules of :data:`MODULES` with mypyc into ``_compiled/`` beside this file
(``setup.py``: ``pip install .``, ``pip install -e .``, a wheel; ``python -m
coolmuscle.tools.accel build`` compiles them again in place; docs/performance.md).
The build writes a manifest last: what it compiled, or why it kept the sources (no C
compiler, ``COOLMUSCLE_COMPILE=0``).  The compiled modules are loaded instead of the
sources only when all of these hold:

* the manifest names this interpreter (``sys.implementation.cache_tag``);
* the digest of the sources it was built from equals the digest of the sources beside
  it now (one edited module turns the whole set off: compiled modules call each other
  directly, so a stale one would still run inside a fresh one).  An installed wheel's
  sources are the ones it was built from, so its digest matches;
* ``COOLMUSCLE_PURE`` is unset, empty or ``0`` (``COOLMUSCLE_PURE=1`` runs the sources);
* the shared library loads (one ``dlopen``, about 1 ms).

Otherwise nothing changes: the sources run, and :func:`describe` says why (``coolmuscle
--version``).  The compiled code is the same source, so the numbers are the same
(tests/test_accel.py and tests/test_packaging.py run both and compare them byte for byte).
"""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import json
import os
import sys
from pathlib import Path
from types import ModuleType
from typing import Sequence

#: The modules compiled, in the order hashed.  Leaves of the import graph first.
MODULES: tuple[str, ...] = (
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
    "coolmuscle.motor.status",
    "coolmuscle.motor.supervision.push",
    "coolmuscle.motor.supervision.faults",
    "coolmuscle.motor.programs.bankcheck",
    "coolmuscle.motor.supervision.sensors",
    "coolmuscle.motor.supervision.origin",
    "coolmuscle.motor.supervision.supervisor",
    "coolmuscle.motor.motor",
    "coolmuscle.chain.bus",
    "coolmuscle.frontends.ethercat.cia402",
    "coolmuscle.frontends.ethercat.dictionary",
    "coolmuscle.frontends.ethercat.bridge.modes",
    "coolmuscle.frontends.ethercat.bridge.cpio",
    "coolmuscle.frontends.ethercat.bridge.csp",
    "coolmuscle.frontends.ethercat.bridge.homing",
    "coolmuscle.frontends.ethercat.bridge.axis",
    "coolmuscle.frontends.ethercat.bridge.drive",
    "coolmuscle.tools.script.record",
)

PACKAGE_DIR = Path(__file__).resolve().parent
BUILD_DIR = PACKAGE_DIR / "_compiled"
MANIFEST_NAME = "manifest.json"

#: How to compile them again, for the reasons that name it.
REBUILD = "pip install again, or python -m coolmuscle.tools.accel build"

#: Why the compiled modules are (not) in use: ``active``, ``reason`` and, when in use,
#: ``mypyc`` (the version that compiled them).
state: dict[str, object] = {"active": False, "reason": "not installed yet"}


def source_path(module: str) -> Path:
    """The source file of one of :data:`MODULES`."""
    parts = module.split(".")[1:]
    return PACKAGE_DIR.joinpath(*parts[:-1], parts[-1] + ".py")


def source_digest(modules: Sequence[str] = MODULES) -> str:
    """BLAKE2b over the names and sources of ``modules``.

    BLAKE2b rather than :mod:`hashlib`'s SHA-256: every start computes it, and
    importing :mod:`hashlib` loads OpenSSL (about 11 M instructions, 2 % of the start
    of ``coolmuscle run``); ``_blake2`` is built into CPython."""
    try:
        from _blake2 import blake2b
    except ImportError:                   # an interpreter built without it
        from hashlib import blake2b
    h = blake2b(digest_size=32)
    for name in modules:
        h.update(name.encode() + b"\0")
        h.update(source_path(name).read_bytes())
        h.update(b"\0")
    return h.hexdigest()


class _CompiledFinder:
    """A meta path finder that answers for the compiled modules only."""

    def __init__(self, files: dict[str, Path]) -> None:
        self.files = files

    def find_spec(self, fullname: str, path: object = None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        found = self.files.get(fullname)
        if found is None:
            return None
        loader = importlib.machinery.ExtensionFileLoader(fullname, str(found))
        return importlib.util.spec_from_file_location(fullname, found, loader=loader)

    def invalidate_caches(self) -> None:
        pass


def load_manifest(build_dir: Path | None = None) -> dict[str, object] | None:
    """The manifest of ``build_dir`` (default :data:`BUILD_DIR`) as written, or ``None``
    when there is none; ``ValueError`` when it is not a JSON object."""
    path = (BUILD_DIR if build_dir is None else build_dir) / MANIFEST_NAME
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    if not isinstance(data, dict):
        raise ValueError("not a JSON object")
    return data


def read_manifest(build_dir: Path | None = None) -> tuple[dict[str, Path] | None, str]:
    """The compiled files of ``build_dir`` (default :data:`BUILD_DIR`) by module name
    when they are current, else ``None``; and the reason, in words."""
    build_dir = BUILD_DIR if build_dir is None else build_dir
    try:
        data = load_manifest(build_dir)
    except (OSError, ValueError) as exc:
        return None, f"manifest unreadable: {exc}"
    if data is None:
        return None, f"not compiled; {REBUILD}"
    if data.get("compiled") is False:
        return None, f"not compiled at install time: {data.get('reason', 'no reason given')}"
    listed, built = data.get("modules"), data.get("files")
    if not isinstance(listed, list) or not isinstance(built, dict):
        return None, "manifest malformed"
    if data.get("cache_tag") != sys.implementation.cache_tag:
        return None, f"compiled for {data.get('cache_tag')}, this is {sys.implementation.cache_tag}"
    if tuple(listed) != MODULES:
        return None, f"compiled for another module list; {REBUILD}"
    try:
        current = source_digest()
    except OSError as exc:
        return None, f"sources unreadable: {exc}"
    if data.get("digest") != current:
        return None, f"a hot module changed since it was compiled; {REBUILD}"
    files = {str(k): build_dir / str(v) for k, v in built.items()}
    if not all(p.is_file() for p in files.values()):
        return None, "a compiled file is missing"
    return files, f"built from the current sources by mypyc {data.get('mypyc', '?')}"


def install() -> None:
    """Put the compiled modules in front of the sources when they are current."""
    if os.environ.get("COOLMUSCLE_PURE", "") not in ("", "0"):
        state.update(active=False, reason="COOLMUSCLE_PURE is set")
        return
    if any(name in sys.modules for name in MODULES):
        state.update(active=False, reason="sources already imported")
        return
    files, reason = read_manifest()
    if files is None:
        state.update(active=False, reason=reason)
        return
    finder = _CompiledFinder(files)
    sys.meta_path.insert(0, finder)
    try:
        for name in files:
            if "." not in name:           # the shared library of the group (mypyc)
                importlib.import_module(name)
    except ImportError as exc:            # a foreign or damaged build: keep the sources
        sys.meta_path.remove(finder)
        state.update(active=False, reason=f"the compiled modules do not load: {exc}")
        return
    state.update(active=True, reason=reason)


def active() -> bool:
    """True when the compiled modules are the ones imported."""
    return bool(state["active"])


def describe() -> str:
    """One line for ``coolmuscle --version``: compiled, or the sources and why."""
    if active():
        return f"hot modules: compiled ({len(MODULES)} modules {state['reason']})"
    return f"hot modules: sources ({state['reason']})"
