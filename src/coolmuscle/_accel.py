"""Compiled copies of the model's hot modules (mypyc), used only when they are current.

The servo and load model, the planner, the kernel and the alarm watchers are plain
Python (the code one reads next to the manual).  ``python -m coolmuscle.tools.accel
build`` compiles the modules of :data:`MODULES` with mypyc into ``_compiled/`` beside
this file (scripts/_env.sh does it after installing; docs/performance.md).  They are
loaded instead of the sources only when all of these hold:

* the build's manifest names this interpreter (``sys.implementation.cache_tag``);
* the digest of the sources it was built from equals the digest of the sources now
  (one edited module turns the whole set off: compiled modules call each other
  directly, so a stale one would still run inside a fresh one);
* ``COOLMUSCLE_PURE`` is unset, empty or ``0`` (``COOLMUSCLE_PURE=1`` runs the sources).

Otherwise nothing changes: the sources run.  The compiled code is the same source, so
the numbers are the same (tests/test_accel.py runs both and compares them byte for byte).
"""

from __future__ import annotations

import hashlib
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
    "coolmuscle.motor.signals.analog",
    "coolmuscle.motor.signals.analog_output",
    "coolmuscle.frontends.ethercat.cia402",
    "coolmuscle.frontends.ethercat.dictionary",
    "coolmuscle.frontends.ethercat.bridge.modes",
    "coolmuscle.frontends.ethercat.bridge.cpio",
    "coolmuscle.frontends.ethercat.bridge.csp",
    "coolmuscle.frontends.ethercat.bridge.homing",
    "coolmuscle.frontends.ethercat.bridge.axis",
    "coolmuscle.frontends.ethercat.bridge.drive",
)

PACKAGE_DIR = Path(__file__).resolve().parent
BUILD_DIR = PACKAGE_DIR / "_compiled"
MANIFEST = BUILD_DIR / "manifest.json"

#: Why the compiled modules are (not) in use, for ``coolmuscle.tools.accel status``.
state: dict[str, object] = {"active": False, "reason": "not installed yet"}


def source_path(module: str) -> Path:
    """The source file of one of :data:`MODULES`."""
    parts = module.split(".")[1:]
    return PACKAGE_DIR.joinpath(*parts[:-1], parts[-1] + ".py")


def source_digest(modules: Sequence[str] = MODULES) -> str:
    """SHA-256 over the names and sources of ``modules``."""
    h = hashlib.sha256()
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


def _read_manifest() -> tuple[dict[str, Path] | None, str]:
    try:
        data = json.loads(MANIFEST.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None, "not built (python -m coolmuscle.tools.accel build)"
    except (OSError, ValueError) as exc:
        return None, f"manifest unreadable: {exc}"
    if not isinstance(data, dict) or not isinstance(data.get("files"), dict):
        return None, "manifest malformed"
    if data.get("cache_tag") != sys.implementation.cache_tag:
        return None, f"built for {data.get('cache_tag')}, not {sys.implementation.cache_tag}"
    if tuple(data.get("modules", ())) != MODULES:
        return None, "built for another module list"
    try:
        current = source_digest()
    except OSError as exc:
        return None, f"sources unreadable: {exc}"
    if data.get("digest") != current:
        return None, "sources changed since the build (rebuild to use it)"
    files = {str(k): BUILD_DIR / str(v) for k, v in data["files"].items()}
    if not all(p.is_file() for p in files.values()):
        return None, "a compiled file is missing"
    return files, "built from the current sources"


def install() -> None:
    """Put the compiled modules in front of the sources when they are current."""
    if os.environ.get("COOLMUSCLE_PURE", "") not in ("", "0"):
        state.update(active=False, reason="COOLMUSCLE_PURE is set")
        return
    if any(name in sys.modules for name in MODULES):
        state.update(active=False, reason="sources already imported")
        return
    files, reason = _read_manifest()
    if files is None:
        state.update(active=False, reason=reason)
        return
    sys.meta_path.insert(0, _CompiledFinder(files))
    state.update(active=True, reason=reason)


def active() -> bool:
    """True when the compiled modules are the ones imported."""
    return bool(state["active"])
