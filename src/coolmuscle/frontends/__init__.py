"""The front doors: each translates one protocol to the device API (:mod:`coolmuscle.device`).

- :mod:`.transports`: byte pipes for the host line (TCP, pty, stdio, serial, COM1) and Modbus TCP;
- :mod:`.urlhandler`: pyserial's ``coolmuscle://`` URL.
"""
