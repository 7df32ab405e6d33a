"""Importing coolmuscle changes nothing in the process (coolmuscle/__init__.py, the package
docstring): the public names, loaded on first use; one version.

A library's import must leave its user's process as it was: no patched module
(:mod:`dataclasses`, pyserial and its loader), no signal handler, no exit hook, no
import hook, no file of the package opened beyond the modules' own code.  Each check runs
in a fresh interpreter (:data:`PROBE`) that imports ``coolmuscle`` and then every
module of the package (a module that needs an optional peer this environment lacks is
skipped, and named), compiled and with ``COOLMUSCLE_PURE=1``.  The process's state
(:data:`SNAPSHOT`) is taken before and after; the modules outside the package that the
import brings in are imported first, in a first interpreter's order, so what they do
when they load (``logging`` registers an exit hook) is not counted against coolmuscle.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import coolmuscle

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = Path(coolmuscle.__file__).resolve().parent

#: What "the process's state" is: every value of dataclasses' and builtins' namespaces,
#: the handler of every signal, the exit hooks, the import hooks and path, the hooks of
#: sys, pyserial's list of URL packages, threads, the environment, the working folder.
SNAPSHOT = r"""
def snapshot():
    import atexit, builtins, dataclasses, os, signal, sys, threading, warnings
    handlers = {}
    for sig in sorted(signal.valid_signals()):
        try:
            handlers[int(sig)] = repr(signal.getsignal(sig))
        except (OSError, ValueError):
            pass
    serial = sys.modules.get("serial")
    return {
        "dataclasses": {k: id(v) for k, v in vars(dataclasses).items()},
        "builtins": {k: id(v) for k, v in vars(builtins).items() if k != "_"},
        "signals": handlers,
        "atexit": atexit._ncallbacks(),
        "meta_path": [repr(f) for f in sys.meta_path],
        "path_hooks": [repr(h) for h in sys.path_hooks],
        "sys.path": list(sys.path),
        "sys hooks": [repr(h) for h in (sys.excepthook, sys.unraisablehook,
                                        sys.displayhook, sys.breakpointhook)],
        "pyserial": None if serial is None else list(serial.protocol_handler_packages),
        "threads": threading.active_count(),
        "environ": dict(os.environ),
        "cwd": os.getcwd(),
        "warnings": len(warnings.filters),
    }
"""

#: The fresh interpreter: argv[1] the package folder, argv[2] a JSON list of modules to
#: import first (or "-": none).  Prints what changed, what was opened, what loaded.  Its
#: ``argv[0]`` names a program ``coolmuscle``: only the command's entry point installs
#: the command's signal handlers, whatever the program importing the library is called.
PROBE = SNAPSHOT + r"""
import importlib, importlib.util, json, os, pkgutil, sys
package_dir = os.path.realpath(sys.argv[1])
sys.argv[0] = os.path.join(os.getcwd(), "coolmuscle")   # a program of that name, too
for name in json.loads(sys.argv[2]) if sys.argv[2] != "-" else ():
    try:
        importlib.import_module(name)
    except BaseException:                    # a module that loads only through its parent
        pass
opened = []
sys.addaudithook(lambda event, args: opened.append(args[0]) if event == "open" else None)
before = snapshot()
import coolmuscle
imported, skipped = [], {}
for info in pkgutil.walk_packages(coolmuscle.__path__, "coolmuscle."):
    if info.name.rsplit(".", 1)[-1] == "__main__":     # programs, not library modules
        continue
    try:
        importlib.import_module(info.name)
        imported.append(info.name)
    except ModuleNotFoundError as exc:
        if exc.name is None or exc.name.startswith("coolmuscle"):
            raise
        skipped[info.name] = exc.name
after = snapshot()
changed = {k: [before[k], after[k]] for k in before if before[k] != after[k]}
own = set()
for module in list(sys.modules.values()):
    path = getattr(module, "__file__", None)
    if path:
        own.add(os.path.realpath(path))
        if path.endswith(".py"):
            own.add(os.path.realpath(importlib.util.cache_from_source(path)))
def ours(path):
    path = os.path.realpath(os.fsdecode(path))
    return path.startswith(package_dir + os.sep) and not any(
        path == p or path.startswith(p + ".") for p in own)      # .pyc.<id> being written
loader = getattr(sys.modules.get("serial"), "__spec__", None)
json.dump({"changed": changed,
           "opened": sorted({os.fsdecode(p) for p in opened
                             if isinstance(p, (str, bytes)) and ours(p)}),
           "imported": imported, "skipped": skipped,
           "serial loader patched": loader is not None
                                    and "exec_module" in vars(loader.loader),
           "modules": [m for m in sys.modules if not m.startswith("coolmuscle")]},
          sys.stdout)
"""


def probe(first: list[str] | None, pure: bool) -> dict[str, object]:
    env = {k: v for k, v in os.environ.items() if k != "COOLMUSCLE_PURE"}
    env["PYTHONPATH"] = str(PACKAGE.parent)
    if pure:
        env["COOLMUSCLE_PURE"] = "1"
    args = [sys.executable, "-c", PROBE, str(PACKAGE), "-" if first is None else json.dumps(first)]
    done = subprocess.run(args, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    result: dict[str, object] = json.loads(done.stdout)
    return result


@pytest.mark.parametrize("pure", [False, True], ids=["as built", "COOLMUSCLE_PURE"])
def test_importing_coolmuscle_and_every_module_changes_nothing(pure: bool) -> None:
    alone = probe(None, pure)              # pyserial loads after coolmuscle here
    assert alone["serial loader patched"] is False
    changed = alone["changed"]
    assert isinstance(changed, dict)
    assert changed["pyserial"] == [None, ["serial.urlhandler"]]      # loaded, as it comes
    imported, skipped = alone["imported"], alone["skipped"]
    assert isinstance(imported, list) and isinstance(skipped, dict)
    every = {".".join(("coolmuscle",) + p.relative_to(PACKAGE).with_suffix("").parts)
             .removesuffix(".__init__") for p in PACKAGE.rglob("*.py")
             if p.name != "__main__.py" and "__pycache__" not in p.parts}
    assert every - {"coolmuscle"} <= set(imported) | set(skipped), \
        every - set(imported) - set(skipped)
    for peer in set(skipped.values()):           # optional peers, truly absent here
        with pytest.raises(ModuleNotFoundError):
            __import__(peer)
    modules = alone["modules"]
    assert isinstance(modules, list)
    result = probe(modules, pure)          # the same, what it loads from elsewhere loaded first
    assert result["changed"] == {}
    assert result["opened"] == []
    assert result["serial loader patched"] is False


#: After ``import coolmuscle`` alone: what loaded, and the public names.
LAZY = r"""
import json, sys
before = set(sys.modules)
import coolmuscle
loaded = sorted(set(sys.modules) - before)
names = {n: f"{getattr(coolmuscle, n).__module__}.{getattr(coolmuscle, n).__qualname__}"
         for n in coolmuscle.__all__ if n != "__version__"}
try:
    coolmuscle.NoSuchName
except AttributeError as exc:
    missing = str(exc)
json.dump({"loaded": loaded, "names": names, "dir": dir(coolmuscle), "missing": missing},
          sys.stdout)
"""


def test_import_coolmuscle_loads_nothing_heavy_and_the_names_load_on_use() -> None:
    env = {k: v for k, v in os.environ.items() if k != "COOLMUSCLE_PURE"}
    env["PYTHONPATH"] = str(PACKAGE.parent)
    done = subprocess.run([sys.executable, "-c", LAZY], env=env, capture_output=True,
                          text=True, check=True, timeout=60)
    out = json.loads(done.stdout)
    ours = {m for m in out["loaded"] if m.startswith("coolmuscle")}
    assert {"coolmuscle", "coolmuscle._accel"} <= ours <= {
        "coolmuscle", "coolmuscle._accel", "coolmuscle._build_stamp"}
    assert not {"typing", "dataclasses", "pathlib", "serial", "asyncio"} & set(out["loaded"])
    assert out["names"] == {
        "Chain": "coolmuscle.chain.daisy.Chain",
        "Kernel": "coolmuscle.sim.kernel.Kernel",
        "seconds": "coolmuscle.sim.kernel.seconds",
        "Device": "coolmuscle.device.api.Device",
        "Event": "coolmuscle.device.api.Event",
        "connect": "coolmuscle.client.sync.connect",
        "connect_async": "coolmuscle.client.aio.connect_async",
        "Version": "coolmuscle.client.replies.Version",
        "Ux": "coolmuscle.motor.status.Ux",
        "CoolMuscleError": "coolmuscle.errors.CoolMuscleError",
        "register_url_handler": "coolmuscle.register_url_handler",
    }
    assert set(coolmuscle.__all__) <= set(out["dir"])
    assert out["missing"] == "module 'coolmuscle' has no attribute 'NoSuchName'"


def test_one_version_read_by_the_build_and_printed_by_the_command() -> None:
    """pyproject.toml has no version of its own: setuptools reads ``coolmuscle.__version__``
    (statically, without importing the package), and ``coolmuscle --version`` prints it."""
    from setuptools.config.expand import read_attr

    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert "version" not in project["project"] and "version" in project["project"]["dynamic"]
    attr = project["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    assert attr == "coolmuscle.__version__"
    assert read_attr(attr, package_dir={"": "src"}, root_dir=ROOT) == coolmuscle.__version__
    env = {k: v for k, v in os.environ.items() if k != "COOLMUSCLE_PURE"}
    env["PYTHONPATH"] = str(PACKAGE.parent)
    done = subprocess.run([sys.executable, "-m", "coolmuscle", "--version"], env=env,
                          capture_output=True, text=True, check=True, timeout=60)
    assert done.stdout.splitlines()[0] == f"coolmuscle {coolmuscle.__version__}"
