"""pyserial URL handlers of coolmuscle (``coolmuscle://``, see protocol_coolmuscle.py).

pyserial finds ``protocol_<scheme>`` modules in the packages listed in
``serial.protocol_handler_packages``; :func:`register` adds this package there.
``import coolmuscle`` calls it.  The handler module itself is imported only when a
``coolmuscle://`` URL is opened.
"""

from __future__ import annotations

PACKAGE = "coolmuscle.frontends.urlhandler"


def register() -> None:
    """Make ``serial.serial_for_url("coolmuscle://...")`` work (idempotent)."""
    import serial

    if PACKAGE not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(PACKAGE)
