"""pyserial URL handlers of coolmuscle (``coolmuscle://``, see protocol_coolmuscle.py).

pyserial finds ``protocol_<scheme>`` modules in the packages listed in
``serial.protocol_handler_packages``; :func:`register` adds this package there.
``import coolmuscle`` calls it.  The handler module itself is imported only when a
``coolmuscle://`` URL is opened, and pyserial only when something imports it: if
it is not loaded yet, the package is added the moment it loads (so the command line
starts without it, and a stop signal in its first instants finds our handlers
installed; docs/reliability.md "signals").
"""

from __future__ import annotations

import importlib.util
import sys
from types import ModuleType
from typing import TYPE_CHECKING, Sequence

if TYPE_CHECKING:
    from importlib.machinery import ModuleSpec

PACKAGE = "coolmuscle.frontends.urlhandler"


def _add(serial: ModuleType) -> None:
    packages = getattr(serial, "protocol_handler_packages", None)
    if packages is not None and PACKAGE not in packages:
        packages.append(PACKAGE)


class _WhenSerialLoads:
    """A meta path finder (importlib.abc.MetaPathFinder's protocol, not imported: it is
    slow to load) that adds the package to pyserial's list right after ``serial`` loads."""

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: ModuleType | None = None) -> "ModuleSpec | None":
        if fullname != "serial":
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)       # once: let the real finders find it
        spec = importlib.util.find_spec("serial")
        loader = spec.loader if spec is not None else None
        exec_module = getattr(loader, "exec_module", None)
        if exec_module is None:
            return spec

        def exec_and_register(module: ModuleType) -> None:
            exec_module(module)
            _add(module)
        loader.exec_module = exec_and_register  # type: ignore[union-attr,method-assign]
        return spec


def register() -> None:
    """Make ``serial.serial_for_url("coolmuscle://...")`` work (idempotent)."""
    serial = sys.modules.get("serial")
    if serial is not None:
        _add(serial)
    elif not any(isinstance(f, _WhenSerialLoads) for f in sys.meta_path):
        sys.meta_path.insert(0, _WhenSerialLoads())
