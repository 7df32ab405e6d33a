"""The motor's own firmware Modbus (cml-users-guide.txt 5.6): pure protocol logic, no I/O.

K81 hands COM0 to Modbus RTU and the final motor of a chain is the COM1 host: both are
what the firmware does, so they live with the chain, written as clients of the device
API (docs/architecture.md).

* :mod:`.registers` -- the register map of 5.6.7 over the device API;
* :mod:`.slave` -- request PDU -> response PDU: addressing (K81, K84), FC03/04/16,
  CML commands, exceptions 01/02, broadcast;
* :mod:`.rtu` -- CRC-16, RTU frames, the 5.6.2 silent interval in virtual time and
  COM0 in Modbus mode (K81 ≠ 0, the ``FFFFFFFFF`` escape of 5.6.9);
* :mod:`.master` -- COM1 as a Modbus host for the I/O slave "final ID + 1".

Front ends that do I/O live in :mod:`coolmuscle.frontends.transports` (``modbus_tcp``,
``serial_line``).  See docs/modbus.md.
"""

from .master import Com1Port
from .rtu import RtuSlaveLine, crc16, rtu_frame, split_rtu_frame
from .slave import ModbusSlave

__all__ = ["Com1Port", "ModbusSlave", "RtuSlaveLine", "crc16", "rtu_frame", "split_rtu_frame"]
