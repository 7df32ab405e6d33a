"""Byte transports for the host line, and their lazy registry.

This package owns the byte pipes between a host program and the motor's host line
(:class:`coolmuscle.device.hostline.HostLine`): ``tcp`` (asyncio server, many clients),
``pty`` (a pseudo-terminal serial programs open as a port), ``rfc2217`` (a serial port
over Telnet, RFC 2217) and ``stdio``.  They move
bytes only; line discipline, echo and delimiters are the model's.

The registry maps a name to ``"module:attribute"`` and imports the module only when
that transport is chosen, so a broken or heavy back end never costs the others.
Third-party back ends register under the ``coolmuscle.frontends.transports`` entry-point
group.  A back end that fails to import raises :class:`TransportError` naming the
module and the cause; it is never reported as "unknown".
"""

from __future__ import annotations

import importlib
import importlib.metadata
from typing import TYPE_CHECKING, Any

from ...errors import TransportError

if TYPE_CHECKING:
    from .base import Transport

#: Built-in back ends: name -> "module:attribute".
BUILTIN: dict[str, str] = {
    "tcp": "coolmuscle.frontends.transports.tcp:TcpTransport",
    "pty": "coolmuscle.frontends.transports.pty:PtyTransport",
    "rfc2217": "coolmuscle.frontends.transports.rfc2217:Rfc2217Transport",
    "stdio": "coolmuscle.frontends.transports.stdio:StdioTransport",
    "modbus-tcp": "coolmuscle.frontends.transports.modbus_tcp:ModbusTcpTransport",
    "modbus-rtu": "coolmuscle.frontends.transports.serial_line:ModbusRtuTransport",
    "serial-device": "coolmuscle.frontends.transports.serial_line:SerialTransport",
    "com1": "coolmuscle.frontends.transports.serial_line:Com1Transport",
    "ethercat": "coolmuscle.frontends.ethercat.transport:EthercatTransport",
    "enip": "coolmuscle.frontends.enip.server:EnipTransport",
}

#: Entry-point group for third-party transports (pyproject ``[project.entry-points]``).
ENTRY_POINT_GROUP = "coolmuscle.transports"

_loaded: dict[str, type[Transport]] = {}


def _entry_points() -> dict[str, str]:
    try:
        eps = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
    except Exception:  # broken metadata must not hide the built-ins
        return {}
    return {ep.name: ep.value for ep in eps}


def registry() -> dict[str, str]:
    """All known transports, name -> ``"module:attribute"`` (built-ins win)."""
    return {**_entry_points(), **BUILTIN}


def names() -> list[str]:
    """Sorted names of all known transports (nothing is imported)."""
    return sorted(registry())


def load(name: str) -> type[Transport]:
    """Import and return the transport class registered as ``name``.

    Raises :class:`TransportError` for an unknown name (listing the known ones) or
    when the back end's module cannot be imported (naming module and cause).
    """
    if name in _loaded:
        return _loaded[name]
    table = registry()
    target = table.get(name)
    if target is None:
        raise TransportError(f"unknown transport {name!r}; known: {', '.join(sorted(table))}")
    module_name, _, attr = target.partition(":")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:
        raise TransportError(f"transport {name!r}: cannot import module {module_name!r}: "
                             f"{type(exc).__name__}: {exc}") from exc
    try:
        found: Any = getattr(module, attr) if attr else module    # as the entry point says
    except AttributeError as exc:
        raise TransportError(f"transport {name!r}: module {module_name!r} has no "
                             f"attribute {attr!r}") from exc
    cls: type[Transport] = found
    _loaded[name] = cls
    return cls


def create(name: str, **options: Any) -> Transport:
    """Instantiate transport ``name`` with keyword ``options``."""
    return load(name)(**options)


__all__ = ["BUILTIN", "ENTRY_POINT_GROUP", "TransportError", "create", "load", "names", "registry"]
