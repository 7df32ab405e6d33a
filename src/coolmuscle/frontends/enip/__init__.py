"""The CM1 EtherNet/IP interface module (cm1-ethernetip-interface-manual.txt; docs/enip.md).

An adapter (target) in front of a virtual CM1: encapsulation over TCP/UDP 44818,
the CIP objects (Identity, Message Router, Assembly 0x65/0x66/0x80, Connection
Manager, TCP/IP, Ethernet Link, vendor class 0x64), Class 1 I/O on UDP 2222 and the
EDS file, all from one set of definitions (:mod:`.cm1.objects`).  The module talks to
the motor only through the device API (:mod:`.cm1.adapter`).

* :mod:`.cip`: the CIP and encapsulation machinery (encapsulation, paths and status,
  the object service, Connection Manager, connections, router, producer); it imports
  nothing of the CM1.
* :mod:`.cm1`: the CM1's facts, its objects, the module over the device API, the EDS.
* :mod:`.server`: the transport (sockets, timers) that joins them.  The ``coolmuscle
  enip`` command is :mod:`coolmuscle.tools.cli.enip`.
"""

from __future__ import annotations

__all__: list[str] = []
