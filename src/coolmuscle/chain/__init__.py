"""The daisy chain of up to 15 motors and what surrounds them.

- :mod:`.daisy`: :class:`Chain`, motors 1..N behind one host line; it implements the
  device API (:mod:`coolmuscle.device`).
- :mod:`.links`: wire time between chained motors at K65.
- :mod:`.power`: a chained motor powered off and on again (wire faults, docs/wire-faults.md).
- :mod:`.machine`: machine files (TOML): the load, sensors and faults around a motor.
- :mod:`.modbus`: the motors' own Modbus firmware (CML guide 5.6): COM0 RTU slave, COM1 host.
"""

from .daisy import Chain

__all__ = ["Chain"]
