"""The CM1 EtherNet/IP interface module (cm1-ethernetip-interface-manual.txt; docs/enip.md).

An adapter (target) in front of a virtual CM1: encapsulation over TCP/UDP 44818,
the CIP objects (Identity, Message Router, Assembly 0x65/0x66/0x80, Connection
Manager, TCP/IP, Ethernet Link, vendor class 0x64), Class 1 I/O on UDP 2222 and the
EDS file, all from one set of definitions (:mod:`.objects`).  The module talks to
the motor only through the device API (:mod:`.adapter`).

Modules: :mod:`.encapsulation` (framing, sessions), :mod:`.cip` (paths, status),
:mod:`.objects`, :mod:`.connmgr` (Forward_Open/Close), :mod:`.io` (connections),
:mod:`.router`, :mod:`.adapter`, :mod:`.eds`, :mod:`.server` (the transport).
"""

from __future__ import annotations

__all__: list[str] = []
