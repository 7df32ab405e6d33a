"""The CIP objects of the CM1 EtherNet/IP module: one definition, read by the router and the EDS.

* Identity (0x01), Message Router (0x02), Assembly (0x04: 0x65 input 8 bytes, 0x66
  output 14 bytes, 0x80 configuration 0 bytes; cm1-ethernetip-interface-manual.txt
  3.1, 3.2, 3.3), Connection Manager (0x06, its services are in
  :mod:`..cip.connmgr`), TCP/IP Interface (0xF5), Ethernet Link (0xF6) and the vendor
  class 0x64 whose instance 1 attribute 0x64 is the communication error code (3.1.1).
  TCP/IP attribute 13, the encapsulation inactivity timeout, is settable
  (:attr:`ObjectModel.inactivity`; the server closes idle TCP connections by it).
* :data:`IDENTITY`, :data:`ASSEMBLIES`, :data:`EXCLUSIVE_OWNER` and
  :data:`DESCRIPTION` are the static facts (the CIP machinery is configured by
  :data:`DESCRIPTION`, the EDS is written from them); :class:`ObjectModel` builds the
  module's object table with the CIP object service of :mod:`..cip.objects`, which
  serves Get_Attribute_Single, Set_Attribute_Single and Get_Attributes_All over it.

A Set of the output assembly takes its exact size, or its size followed by exactly
the empty route path pycomm3 sends (``00 00``); short and long data are 0x13 and 0x15,
a write while an I/O connection owns it 0x10 (docs/fidelity.md "EtherNet/IP").
Identity Reset (type 0 or 1) restarts the module: its connections close, its outputs
return to the power-up image; the motor, a separate device behind the serial line,
is not reset.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Protocol

from ..cip import messages as cip
from ..cip.description import AdapterDescription, AssemblyInfo, ConnectionInfo, IdentityInfo
from ..cip.messages import CipError
from ..cip.objects import (
    ASSEMBLY_CLASS,
    CONNECTION_MANAGER_CLASS,
    ETHERNET_LINK_CLASS,
    IDENTITY_CLASS,
    ROUTER_CLASS,
    TCPIP_CLASS,
    Attribute,
    EncapsulationTimeout,
    Instance,
    ObjectService,
    ObjectTable,
    class_attributes,
    ethernet_link_instance,
    exact_data,
    identity_instance,
    router_instance,
    tcpip_instance,
    u16,
)

# -- static facts (also the EDS) -----------------------------------------------------

#: Invented where the manual is silent (docs/fidelity.md): vendor id and product code
#: are not published for the CM1 module; device type 0x2B is "generic device, keyable";
#: revision 1.7 follows the manual's document version 1.07.
IDENTITY = IdentityInfo(vendor_id=0x0586, device_type=0x2B, product_code=0x0001,
                        revision=(1, 7), serial=0x00A0_0001,
                        product_name="Cool Muscle 1 EtherNet/IP",
                        vendor_name="Myostat Motion Control Inc")

INPUT_INSTANCE, OUTPUT_INSTANCE, CONFIG_INSTANCE = 0x65, 0x66, 0x80
ASSEMBLIES: dict[int, AssemblyInfo] = {
    INPUT_INSTANCE: AssemblyInfo(INPUT_INSTANCE, 8, "Input (T->O)", False),
    OUTPUT_INSTANCE: AssemblyInfo(OUTPUT_INSTANCE, 14, "Output (O->T)", True),
    CONFIG_INSTANCE: AssemblyInfo(CONFIG_INSTANCE, 0, "Configuration", True),
}

#: The I/O connection the module offers (manual ch. 4): 0x66 -> 0x65, config 0x80.
EXCLUSIVE_OWNER = ConnectionInfo("Exclusive Owner", OUTPUT_INSTANCE, INPUT_INSTANCE,
                                 CONFIG_INSTANCE, ASSEMBLIES[OUTPUT_INSTANCE].size,
                                 ASSEMBLIES[INPUT_INSTANCE].size,
                                 2_000, 10_000_000, 10_000, True)

VENDOR_CLASS = 0x64
VENDOR_ATTRIBUTE = 0x64
CLASSES = (IDENTITY_CLASS, ROUTER_CLASS, ASSEMBLY_CLASS, CONNECTION_MANAGER_CLASS,
           VENDOR_CLASS, TCPIP_CLASS, ETHERNET_LINK_CLASS)
#: Connections the module takes, per kind (its EDS [Capacity]; docs/fidelity.md): the
#: one Class 1 exclusive owner, and three class 3 connections to the Message Router.
MAX_IO_CONNECTIONS = 1
MAX_MSG_CONNECTIONS = 3

#: What the CIP machinery (connection manager, connection table) serves.
DESCRIPTION = AdapterDescription(IDENTITY, EXCLUSIVE_OWNER, MAX_IO_CONNECTIONS,
                                 MAX_MSG_CONNECTIONS)

#: Ethernet Link instance 1: 100 Mbit/s, link active, full duplex, negotiated; a locally
#: administered MAC address.
LINK_SPEED, LINK_FLAGS = 100, 0x0F
MAC = bytes((0x02, 0x00, 0xC0, 0x4D, 0x00, 0x01))
HOSTNAME = "coolmuscle-cm1"


class Images(Protocol):
    """What the objects read and write of the module (:class:`.adapter.Cm1Module`)."""

    def input_image(self) -> bytes: ...

    def output_image(self) -> bytes: ...

    def write_output(self, data: bytes) -> None: ...

    def comm_error(self) -> int: ...

    def identity_status(self) -> int: ...


class ObjectModel(ObjectService):
    """The CM1 module's objects, served by the CIP object service."""

    def __init__(self, module: Images, *, host: str = "127.0.0.1",
                 output_owned: Callable[[], bool] = lambda: False,
                 reset: Callable[[], None] = lambda: None) -> None:
        self.module = module
        self.host = host
        self.output_owned = output_owned
        #: TCP/IP attribute 13, read by the server that closes idle TCP connections.
        self.inactivity = EncapsulationTimeout()
        super().__init__(self._build(), reset=reset, out_of_box=self.inactivity.out_of_box)

    def _build(self) -> ObjectTable:
        comm_error = Attribute(lambda: struct.pack("<H", self.module.comm_error()))
        return {
            IDENTITY_CLASS: {0: class_attributes(1, 1),
                             1: identity_instance(IDENTITY, self.module.identity_status)},
            ROUTER_CLASS: {0: class_attributes(1, 1),
                           1: router_instance(CLASSES, MAX_MSG_CONNECTIONS)},
            ASSEMBLY_CLASS: {0: class_attributes(2, max(ASSEMBLIES)),
                             **{i: self._assembly(a) for i, a in ASSEMBLIES.items()}},
            CONNECTION_MANAGER_CLASS: {0: class_attributes(1, 1), 1: {}},
            VENDOR_CLASS: {0: class_attributes(1, 1), 1: {VENDOR_ATTRIBUTE: comm_error}},
            TCPIP_CLASS: {0: class_attributes(4, 1),
                          1: tcpip_instance(self.host, HOSTNAME, self.inactivity)},
            ETHERNET_LINK_CLASS: {0: class_attributes(4, 1),
                                  1: ethernet_link_instance(LINK_SPEED, LINK_FLAGS, MAC)},
        }

    def _assembly(self, info: AssemblyInfo) -> Instance:
        if info.instance == INPUT_INSTANCE:
            data = Attribute(self.module.input_image)
        elif info.instance == OUTPUT_INSTANCE:
            data = Attribute(self.module.output_image, self._set_output)
        else:
            data = Attribute(lambda: b"", self._set_config)
        return {3: data, 4: Attribute(u16(info.size))}

    def _set_output(self, data: bytes) -> None:
        data = exact_data(data, ASSEMBLIES[OUTPUT_INSTANCE].size)
        if self.output_owned():
            raise CipError(cip.DEVICE_STATE_CONFLICT)
        self.module.write_output(data)

    @staticmethod
    def _set_config(data: bytes) -> None:
        exact_data(data, ASSEMBLIES[CONFIG_INSTANCE].size)
