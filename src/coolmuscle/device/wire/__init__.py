"""Wire faults: communication faults at every door, deterministic in virtual time
(docs/wire-faults.md).

* :mod:`.vocabulary` -- the doors, their fault kinds and the kinds' parameters (one
  registry: the machine file, the device API and the web page check against it);
* :mod:`.schedule` -- a fault's window in virtual time, its own generator, the record of
  what it did (:class:`WireFaults`, one per device);
* :mod:`.line` -- the host line's faults, where bytes leave the model.

The other doors apply their kinds themselves, asking the device's :class:`WireFaults`
what to do to each message: the chain (``chain/daisy.py``), the motor's Modbus RTU
(``chain/firmware_modbus/rtu.py``), the Modbus TCP door and the CM1 EtherNet/IP module.
"""

from .schedule import (
           MAX_TIME_S,
           SCHEDULE_KEYS,
           ActiveFault,
    Generator,
           WireFault,
           WireFaults,
           WireRecord,
           wire_fault,
)
from .vocabulary import FaultKind, Param, describe, doors, kind_of, kinds, register

__all__ = ["ActiveFault", "FaultKind", "Generator", "MAX_TIME_S", "Param", "SCHEDULE_KEYS",
           "WireFault", "WireFaults", "WireRecord", "describe", "doors", "kind_of", "kinds",
           "register", "wire_fault"]
