"""The compiled code of the methods :mod:`dataclasses` writes for coolmuscle's classes,
kept between runs as Python keeps a module's byte code: a cache the ``coolmuscle``
command installs for its own process (:func:`coolmuscle.tools.cli.entry.main`);
importing coolmuscle never does (docs/performance.md "Starting a run").

At import, :func:`dataclasses.dataclass` writes each class's ``__init__``, ``__repr__``,
``__eq__``, ``__hash__``, ``__setattr__`` ... as Python source text and compiles it with
``exec``: for ``coolmuscle run`` about 370 methods, parsed and compiled at every start
(about a fifth of its CPU time).  :func:`install` puts a cache in front of that
``exec`` for the classes of coolmuscle's own modules: the code objects, keyed by their
source text and ``__future__`` flags, are kept in one file in the package's
``__pycache__``.  The same text compiled the same way (``compile(text, "<string>",
"exec", flags, dont_inherit=True)`` with the flags of the code calling ``exec``, which is
what ``exec`` of a string does) is the same code, so every class is exactly what
:mod:`dataclasses` makes of it: same methods, signatures, annotations, ``repr``,
equality, pickling.

* Only the classes of ``coolmuscle.*`` modules go through it (:func:`_ours`);
  everything else's dataclasses are compiled as always.
* The file is read once, at the first dataclass of the process; new entries are written at
  exit (one ``os.replace``: concurrent processes never see half a file), not at all where
  byte code is not written (``PYTHONDONTWRITEBYTECODE``, ``-B``) or the folder is
  read-only.  A file that does not load (another Python, damaged, truncated) is ignored
  and replaced; one grown beyond :data:`MAX_BYTES` (edited classes leave their old texts
  behind) starts afresh.
* ``COOLMUSCLE_DATACLASS_CACHE=0`` turns it off.
"""

from __future__ import annotations
import __future__

import builtins
import dataclasses
import importlib.util
import marshal
import os
import sys
from pathlib import Path
from types import CodeType, FrameType
from typing import Any

#: The cache file starts afresh beyond this size.
MAX_BYTES = 4 << 20
#: What a cache file must start with: this interpreter's byte code magic, its
#: optimisation level and the marshal format.
HEADER = (importlib.util.MAGIC_NUMBER + bytes([sys.flags.optimize & 0xFF, marshal.version & 0xFF]))

#: Every ``__future__`` feature's compiler flag (what ``exec`` inherits from its caller).
_FUTURE_FLAGS: int = sum(getattr(__future__, name).compiler_flag
                         for name in __future__.all_feature_names)

#: ``dataclasses._process_class`` (where the class being made is the local ``cls``) and
#: how far up from ``exec`` it is looked for (``_create_fn`` <- ``_init_fn`` <- it).
_PROCESS_CLASS: CodeType | None = getattr(getattr(dataclasses, "_process_class", None),
                                          "__code__", None)
_MAX_DEPTH = 6

_state: dict[str, Any] = {"codes": None, "added": 0, "installed": False}


def cache_path() -> Path:
    """The cache file: ``coolmuscle/__pycache__/dataclass-code.<cache tag>.marshal``
    (under ``sys.pycache_prefix`` when that is set, as byte code is)."""
    pseudo_source = Path(__file__).resolve().with_name("dataclass-code.py")
    pyc = Path(importlib.util.cache_from_source(str(pseudo_source)))
    return pyc.with_suffix(".marshal")


def _load() -> dict[tuple[int, str], CodeType]:
    try:
        data = cache_path().read_bytes()
    except OSError:
        return {}
    if not data.startswith(HEADER) or len(data) > MAX_BYTES:
        return {}
    try:
        codes = marshal.loads(data[len(HEADER):])
    except (EOFError, ValueError, TypeError):
        return {}
    if not isinstance(codes, dict):
        return {}
    return {k: v for k, v in codes.items()
            if isinstance(k, tuple) and len(k) == 2 and isinstance(k[0], int)
            and isinstance(k[1], str) and isinstance(v, CodeType)}


def _codes() -> dict[tuple[int, str], CodeType]:
    codes = _state["codes"]
    if codes is None:
        codes = _state["codes"] = _load()
    return codes  # type: ignore[no-any-return]


def _ours(namespace: object, caller: FrameType) -> bool:
    """A class of a coolmuscle module: told by the module globals :mod:`dataclasses`
    passes, or, when those are not a module's (a mypyc-compiled module builds its
    classes before it is in ``sys.modules``: an empty dict, then ``__builtins__``
    only), by the class ``dataclasses._process_class`` (a few frames up) is making.
    Not found: not ours."""
    if not isinstance(namespace, dict):
        return False
    name = namespace.get("__name__")
    if name is not None:
        return str(name).startswith("coolmuscle.")
    frame: FrameType | None = caller
    for _ in range(_MAX_DEPTH):
        if frame is None:
            return False
        if frame.f_code is _PROCESS_CLASS:
            cls = frame.f_locals.get("cls")
            return isinstance(cls, type) and cls.__module__.startswith("coolmuscle.")
        frame = frame.f_back
    return False


def _caller_flags(frame: FrameType) -> int:
    """The ``__future__`` flags ``exec`` of a string takes from the code calling it."""
    return frame.f_code.co_flags & _FUTURE_FLAGS


def cached_exec(source: Any, globals: Any = None, locals: Any = None, /,
                **kwargs: Any) -> None:
    """``exec`` as :mod:`dataclasses` calls it, the compiled text taken from the cache
    for coolmuscle's classes; anything else compiled and run as ``exec`` itself would,
    with the caller's ``__future__`` flags (not this module's)."""
    caller = sys._getframe(1)
    if globals is None:                  # exec's own defaults: the caller's namespaces
        globals = caller.f_globals
        locals = caller.f_locals if locals is None else locals
    if not isinstance(source, str) or kwargs:
        builtins.exec(source, globals, locals, **kwargs)
        return
    flags = _caller_flags(caller)
    if not _ours(globals, caller):
        builtins.exec(compile(source, "<string>", "exec", flags, dont_inherit=True),
                      globals, locals)
        return
    codes = _codes()
    key = (flags, source)
    code = codes.get(key)
    if code is None:
        code = codes[key] = compile(source, "<string>", "exec", flags, dont_inherit=True)
        _state["added"] += 1
    builtins.exec(code, globals, locals)


def save() -> None:
    """Write the cache when this process compiled anything new (at exit)."""
    codes = _state["codes"]
    if not _state["added"] or codes is None or sys.dont_write_bytecode:
        return
    path = cache_path()
    body = HEADER + marshal.dumps(codes)
    if len(body) > MAX_BYTES:
        return
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_bytes(body)
        os.replace(tmp, path)
        _state["added"] = 0
    except OSError:                      # read-only install, full disk: no cache
        try:
            tmp.unlink()
        except OSError:
            pass


def install() -> None:
    """Put the cache in front of :mod:`dataclasses`' ``exec`` (once) and write it at exit:
    for a program (the ``coolmuscle`` command), not for a library import."""
    if _state["installed"] or os.environ.get("COOLMUSCLE_DATACLASS_CACHE", "") == "0":
        return
    import atexit
    dataclasses.exec = cached_exec       # type: ignore[attr-defined]
    atexit.register(save)
    _state["installed"] = True
