"""coolmuscle: a byte-faithful virtual Cool Muscle servo motor and host tools.

What a simulator user needs, loaded on first use (``import coolmuscle`` itself loads
none of it)::

    from coolmuscle import Chain, seconds
    chain = Chain(motors=2)                     # the virtual motors (a Device)
    chain.execute("?96.1")
    chain.kernel.run(until=seconds(1))

    from coolmuscle import connect              # a real or virtual motor over a port
    with connect("coolmuscle://?mode=fast") as m:
        print(m.status)

* :class:`Chain` - up to 15 virtual motors on one host line; it implements
  :class:`Device`, the device API every front end uses, whose :class:`Event` it emits;
* :class:`Kernel`, :func:`seconds` - virtual time (integer nanoseconds);
* :func:`connect`, :func:`connect_async`, :class:`Version` - the host library;
* :class:`Ux` - the 6.6 ``?99`` status flags; :class:`CoolMuscleError` - the root of
  every exception;
* :func:`register_url_handler` - pyserial's ``coolmuscle://`` URL.

Importing coolmuscle changes nothing in the process: no signal handler, exit hook,
import hook or patched module.  It reads the build stamp of the compiled hot modules
(:mod:`coolmuscle._accel`), which says whether they run.  See README.md and docs/.
"""

from . import _accel

_accel.choose(__path__[0])   # the compiled hot modules or the sources (the build stamp)

#: The one place the version is written (pyproject.toml reads it from here).
__version__ = "0.1.0"

__all__ = ["__version__", "Chain", "Kernel", "seconds", "Device", "Event", "connect",
           "connect_async", "Version", "Ux", "CoolMuscleError", "register_url_handler"]

#: Each exported name's module (imported on first use).
_HOMES = {
    "Chain": "coolmuscle.chain",
    "Kernel": "coolmuscle.sim.kernel",
    "seconds": "coolmuscle.sim.kernel",
    "Device": "coolmuscle.device",
    "Event": "coolmuscle.device",
    "connect": "coolmuscle.client",
    "connect_async": "coolmuscle.client",
    "Version": "coolmuscle.client",
    "Ux": "coolmuscle.motor.status",
    "CoolMuscleError": "coolmuscle.errors",
}


def register_url_handler() -> None:
    """Make ``serial.serial_for_url("coolmuscle://...")`` work: pyserial's documented
    ``serial.protocol_handler_packages`` gets coolmuscle's handler package (once).
    :func:`connect` does it itself for a ``coolmuscle://`` URL (docs/transports.md)."""
    from .frontends.urlhandler import register

    register()


def __getattr__(name: str) -> object:
    """The names of :data:`__all__`, imported from their module on first use."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'coolmuscle' has no attribute {name!r}")
    from importlib import import_module

    value = getattr(import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


TYPE_CHECKING = False      # typing.TYPE_CHECKING without importing typing at start
if TYPE_CHECKING:
    from .chain import Chain as Chain
    from .client import Version as Version
    from .client import connect as connect
    from .client import connect_async as connect_async
    from .device import Device as Device
    from .device import Event as Event
    from .errors import CoolMuscleError as CoolMuscleError
    from .motor.status import Ux as Ux
    from .sim.kernel import Kernel as Kernel
    from .sim.kernel import seconds as seconds
del TYPE_CHECKING
