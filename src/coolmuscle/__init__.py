"""coolmuscle: a byte-faithful virtual Cool Muscle servo motor and host tools.

See README.md and docs/.  The public API grows issue by issue; names exported here
are stable.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__", "connect", "connect_async"]


def __getattr__(name: str) -> object:
    """``connect`` / ``connect_async`` load the host library on first use."""
    if name in ("connect", "connect_async"):
        from . import client
        return getattr(client, name)
    raise AttributeError(f"module 'coolmuscle' has no attribute {name!r}")

from .frontends.urlhandler import register as _register_url_handler  # noqa: E402

_register_url_handler()  # serial.serial_for_url("coolmuscle://...")
