"""coolmuscle: a byte-faithful virtual Cool Muscle servo motor and host tools.

See README.md and docs/.  The public API grows issue by issue; names exported here
are stable.
"""

from __future__ import annotations

import os as _os
import sys as _sys


def _run_as_the_command() -> bool:
    """``python -m coolmuscle ...`` (argv[0] is "-m" while the package loads) or the
    ``coolmuscle`` script."""
    if _sys.argv[:1] == ["-m"]:
        orig = list(getattr(_sys, "orig_argv", []))
        return "-m" in orig and orig[orig.index("-m") + 1:][:1] == ["coolmuscle"]
    return _os.path.basename(_sys.argv[0] if _sys.argv else "") == "coolmuscle"


if _run_as_the_command():
    # Started as the command: stop signals are handled from here on,
    # before anything else loads (docs/reliability.md "signals").  A library import
    # leaves the program's signal handlers alone.
    from .tools.cli.stopsignals import install_startup_handlers as _install

    _install()

from . import _dataclass_code  # noqa: E402

_dataclass_code.install()  # the dataclasses' generated methods kept compiled between runs

from . import _accel  # noqa: E402

_accel.choose(__path__[0])  # the compiled hot modules or the sources (the build stamp)

__version__ = "0.1.0"

__all__ = ["__version__", "connect", "connect_async", "Ux", "Version", "CoolMuscleError",
           "register_url_handler"]


def __getattr__(name: str) -> object:
    """``connect`` / ``connect_async`` / ``Version`` load the host library on first use;
    ``Ux`` (the 6.6 ?99 status flags) and ``CoolMuscleError`` (the root of every
    exception) are the names its results and errors carry."""
    if name in ("connect", "connect_async", "Version"):
        from . import client
        return getattr(client, name)
    if name == "Ux":
        from .motor.status import Ux
        return Ux
    if name == "CoolMuscleError":
        from .errors import CoolMuscleError
        return CoolMuscleError
    raise AttributeError(f"module 'coolmuscle' has no attribute {name!r}")



def register_url_handler() -> None:
    """Make ``serial.serial_for_url("coolmuscle://...")`` work: pyserial's documented
    ``serial.protocol_handler_packages`` gets coolmuscle's handler package (once).
    :func:`connect` does it itself for a ``coolmuscle://`` URL (docs/transports.md)."""
    from .frontends.urlhandler import register

    register()
