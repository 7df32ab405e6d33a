"""The cache of the methods :mod:`dataclasses` writes (coolmuscle/_dataclass_code.py),
which the ``coolmuscle`` command installs for its own process.

The classes must be exactly what :mod:`dataclasses` makes of them with and without the
cache; the file must never break a start (damaged, foreign, read-only, ``-B``); only
coolmuscle's own classes go through it; the command installs it and importing
coolmuscle does not (tests/test_import.py checks the whole of :mod:`dataclasses`).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

#: Every dataclass method of every coolmuscle module a wide import loads, described by
#: what makes its code (byte code, constants, names, lines) and its signature.
DUMP = r"""
import dataclasses, importlib, inspect, json, os, re, sys, types
import coolmuscle
from coolmuscle import _dataclass_code as d
d.install()                                 # as the command's entry point does
for name in ("coolmuscle.chain.daisy", "coolmuscle.tools.script.runner",
             "coolmuscle.client", "coolmuscle.tools.cli.app",
             "coolmuscle.frontends.enip.cip.messages", "coolmuscle.frontends.ethercat.bridge.table",
             "coolmuscle.tools.twin.compare", "coolmuscle.chain.machine"):
    importlib.import_module(name)

def code_key(code):
    consts = tuple(code_key(c) if isinstance(c, types.CodeType) else repr(c)
                   for c in code.co_consts)
    return [code.co_code.hex(), consts, code.co_names, code.co_varnames, code.co_freevars,
            code.co_cellvars, code.co_argcount, code.co_posonlyargcount,
            code.co_kwonlyargcount, code.co_flags, code.co_firstlineno, code.co_filename,
            code.co_qualname, code.co_linetable.hex(), code.co_exceptiontable.hex()]

def stable(text):
    # a default that is a function prints its address, which differs between processes
    return re.sub(r" at 0x[0-9a-f]+", " at 0x...", text)

out = {}
for modname, module in sorted(sys.modules.items()):
    if not modname.startswith("coolmuscle"):
        continue
    for cls in list(vars(module).values()):
        if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)
                and cls.__module__ == modname):
            continue
        for attr, value in sorted(vars(cls).items()):
            code = getattr(value, "__code__", None)
            if code is None:
                continue
            out[f"{modname}.{cls.__qualname__}.{attr}"] = [
                code_key(code), stable(str(inspect.signature(value))),
                stable(repr(value.__defaults__))]
        out[f"{modname}.{cls.__qualname__}"] = [repr(cls.__dataclass_params__),
                                               sorted(getattr(cls, "__slots__", ()))]
json.dump({"methods": out, "added": d._state["added"], "installed": d._state["installed"],
           "path": str(d.cache_path())}, sys.stdout)
"""


def _python(code: str, prefix: Path, *flags: str, **env: str) -> dict:
    environ = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    environ.update(PYTHONPYCACHEPREFIX=str(prefix), **env)
    proc = subprocess.run([sys.executable, *flags, "-c", code], capture_output=True,
                          text=True, env=environ, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout)


@pytest.fixture(scope="module")
def dumps(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    prefix = tmp_path_factory.mktemp("pycache")
    off = _python(DUMP, prefix, COOLMUSCLE_DATACLASS_CACHE="0")
    first = _python(DUMP, prefix)                 # compiles, writes the file at exit
    warm = _python(DUMP, prefix)                  # takes every method from the file
    return {"off": off, "first": first, "warm": warm, "prefix": {"path": str(prefix)}}


def test_the_cached_classes_are_what_dataclasses_makes(dumps: dict[str, dict]) -> None:
    off, first, warm = dumps["off"], dumps["first"], dumps["warm"]
    assert not off["installed"] and first["installed"] and warm["installed"]
    methods = [k for k, v in off["methods"].items() if len(v) == 3]
    assert len(methods) > 300                      # __init__, __repr__, __eq__ ... of them all
    assert first["added"] > 300 and warm["added"] == 0   # the warm start compiled nothing
    assert first["methods"] == off["methods"]
    assert warm["methods"] == off["methods"]


def test_the_file_is_where_byte_code_goes(dumps: dict[str, dict]) -> None:
    path = Path(dumps["warm"]["path"])
    assert path.is_relative_to(dumps["prefix"]["path"])      # PYTHONPYCACHEPREFIX honoured
    assert path.name == f"dataclass-code.{sys.implementation.cache_tag}.marshal"
    assert path.is_file() and not list(path.parent.glob("*.tmp"))


START = ("import json, sys; from coolmuscle import _dataclass_code as d; d.install(); "
         "import coolmuscle.chain.daisy; "
         "json.dump({'added': d._state['added'], 'path': str(d.cache_path())}, sys.stdout)")


@pytest.mark.parametrize("content", [b"", b"garbage", b"\x00" * 64, "header"])
def test_a_damaged_or_foreign_file_is_ignored_and_replaced(tmp_path: Path,
                                                           content: bytes | str) -> None:
    path = Path(_python(START, tmp_path)["path"])
    good = path.read_bytes()
    # "header": this interpreter's header, then a truncated body
    path.write_bytes(good[:len(good) // 2] if content == "header" else content)
    again = _python(START, tmp_path)
    assert again["added"] > 100                    # nothing usable was read ...
    assert path.read_bytes() == good               # ... and the file is whole again
    assert _python(START, tmp_path)["added"] == 0


def test_no_file_where_byte_code_is_not_written(tmp_path: Path) -> None:
    """``python -B`` (or ``PYTHONDONTWRITEBYTECODE``): the cache is used, never written."""
    assert _python(START, tmp_path, "-B")["added"] > 100
    assert not list(tmp_path.rglob("dataclass-code.*"))


def test_a_read_only_cache_folder_is_one_no_cache_not_an_error(tmp_path: Path) -> None:
    """The write fails (the file's name taken by a folder: a mode bit would not stop
    root, who runs the suite): the start goes on without a cache."""
    path = Path(_python(START, tmp_path)["path"])
    path.unlink()
    path.mkdir()                                   # os.replace onto a folder fails
    result = _python(START, tmp_path)
    assert result["added"] > 100 and path.is_dir()
    assert not list(path.parent.glob("*.tmp"))     # the half-written file was removed


def test_other_modules_dataclasses_are_not_cached(tmp_path: Path) -> None:
    code = ("import json, sys, dataclasses\n"
            "from coolmuscle import _dataclass_code as d\n"
            "d.install()\n"
            "import coolmuscle.cml.ast\n"
            "@dataclasses.dataclass(frozen=True)\n"
            "class UsersOwn:\n"
            "    a_field_of_the_users: int = 3\n"
            "assert UsersOwn() == UsersOwn(3) and hash(UsersOwn())\n"
            "# a module not (yet) in sys.modules, as a mypyc-compiled one while it loads:\n"
            "# dataclasses passes empty globals, the class's own module decides\n"
            "Loading = type('Loading', (), {'__module__': 'users.loading',\n"
            "               '__annotations__': {'a_field_of_a_loading_module': int}})\n"
            "dataclasses.dataclass(Loading)\n"
            "Ours = type('Ours', (), {'__module__': 'coolmuscle.loading',\n"
            "            '__annotations__': {'a_field_of_ours_loading': int}})\n"
            "dataclasses.dataclass(Ours)\n"
            "codes = d._state['codes'] or {}\n"
            "json.dump({'seen': any('a_field_of_the_users' in t or\n"
            "                       'a_field_of_a_loading_module' in t for _, t in codes),\n"
            "           'ours': any('a_field_of_ours_loading' in t for _, t in codes),\n"
            "           'cached': len(codes),\n"
            "           'annotations': repr(UsersOwn.__init__.__annotations__)}, sys.stdout)\n")
    result = _python(code, tmp_path)
    assert result["cached"] > 0 and not result["seen"] and result["ours"]
    # compiled as exec would in dataclasses (no __future__ flags), not with the flags of
    # the module that holds the cache: the annotations are the classes, not strings
    assert result["annotations"] == "{'a_field_of_the_users': <class 'int'>, 'return': None}"


def test_exec_without_namespaces_uses_the_callers_as_exec_does() -> None:
    from coolmuscle._dataclass_code import cached_exec

    def caller() -> dict[str, object]:
        here: dict[str, object] = {}
        cached_exec("here['x'] = 41 + 1")
        return here
    assert caller() == {"x": 42}


def test_the_command_keeps_the_cache_and_a_library_import_does_not(tmp_path: Path) -> None:
    """``coolmuscle run`` writes the cache at its exit and takes every method from it at
    the next start; importing coolmuscle and its model installs nothing."""
    script = tmp_path / "one.cml"
    script.write_text("?96.1\n")
    environ = {k: v for k, v in os.environ.items()
               if k not in ("PYTHONDONTWRITEBYTECODE", "COOLMUSCLE_DATACLASS_CACHE")}
    environ["PYTHONPYCACHEPREFIX"] = str(tmp_path / "pycache")
    library = _python("import coolmuscle, coolmuscle.chain.daisy, dataclasses, json, sys; "
                      "from coolmuscle import _dataclass_code as d; "
                      "json.dump({'installed': d._state['installed'], "
                      "'exec': getattr(dataclasses, 'exec', None) is d.cached_exec, "
                      "'path': str(d.cache_path())}, sys.stdout)", tmp_path / "pycache")
    assert library["installed"] is False and library["exec"] is False
    assert not Path(library["path"]).exists()
    cached = Path(library["path"])
    written = []
    for _ in range(2):
        subprocess.run([sys.executable, "-m", "coolmuscle", "run", str(script)], env=environ,
                       capture_output=True, check=True, timeout=120)
        assert cached.is_file() and cached.stat().st_size > 10_000
        written.append(cached.stat().st_mtime_ns)
    assert written[0] == written[1]        # the second start compiled nothing new
