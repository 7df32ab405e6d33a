"""pyserial URL handlers of coolmuscle (``coolmuscle://``, see protocol_coolmuscle.py).

pyserial's :func:`serial.serial_for_url` looks for a module ``protocol_<scheme>`` in
each package named in ``serial.protocol_handler_packages``, in order (its documented
way of adding a scheme: "``protocol_handler_packages.append("my_handlers")`` would
extend the search path").  :func:`register` appends this package there; nothing else
does, and importing coolmuscle does not.  :func:`coolmuscle.client.connect` and the
tools that open a ``coolmuscle://`` port call it for their own use::

    import coolmuscle, serial
    coolmuscle.register_url_handler()
    port = serial.serial_for_url("coolmuscle://?mode=fast", timeout=1)

The handler module itself is imported by pyserial when a ``coolmuscle://`` URL is
opened.
"""

from __future__ import annotations

PACKAGE = "coolmuscle.frontends.urlhandler"


def register() -> None:
    """Make ``serial.serial_for_url("coolmuscle://...")`` work: this package appended to
    ``serial.protocol_handler_packages`` once (calling it again changes nothing)."""
    import serial

    if PACKAGE not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(PACKAGE)

