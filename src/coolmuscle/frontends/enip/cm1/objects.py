"""The CIP objects of the CM1 EtherNet/IP module: one definition, read by the router and the EDS.

* Identity (0x01), Message Router (0x02), Assembly (0x04: 0x65 input 8 bytes, 0x66
  output 14 bytes, 0x80 configuration 0 bytes; cm1-ethernetip-interface-manual.txt
  3.1, 3.2, 3.3), Connection Manager (0x06, its services are in :mod:`.connmgr`),
  TCP/IP Interface (0xF5), Ethernet Link (0xF6) and the vendor class 0x64 whose
  instance 1 attribute 0x64 is the communication error code (3.1.1).
* :data:`IDENTITY`, :data:`ASSEMBLIES` and :data:`EXCLUSIVE_OWNER` are the static
  facts; :class:`ObjectModel` serves Get_Attribute_Single, Set_Attribute_Single and
  Get_Attributes_All over them, raising :class:`~.cip.CipError` for every refusal.

Refusals (CIP Vol 1 appendix B; docs/fidelity.md "EtherNet/IP"): an unknown class or
instance is 0x05 (path destination unknown, as ODVA's OpENer answers), a service the
object lacks 0x08 (Identity also has Reset), an attribute it lacks 0x14, a read-only
attribute 0x0E, short and long data 0x13 and 0x15, a write to the output assembly while an
I/O connection owns it 0x10.  The Get services ignore request data after the path (as OpENer
does; pycomm3 sends its route path there by default); a Set of an assembly accepts
its exact size, or its size followed by exactly that empty route path (``00 00``).
"""

from __future__ import annotations

import ipaddress
import struct
from dataclasses import dataclass
from typing import Callable, Protocol

from ..cip import messages as cip
from ..cip.messages import CipError

# -- static facts (also the EDS) -----------------------------------------------------


@dataclass(frozen=True, slots=True)
class IdentityInfo:
    """Identity object instance 1 (CIP Vol 1 5A-2)."""

    vendor_id: int
    device_type: int
    product_code: int
    revision: tuple[int, int]
    serial: int
    product_name: str
    vendor_name: str


#: Invented where the manual is silent (docs/fidelity.md): vendor id and product code
#: are not published for the CM1 module; device type 0x2B is "generic device, keyable";
#: revision 1.7 follows the manual's document version 1.07.
IDENTITY = IdentityInfo(vendor_id=0x0586, device_type=0x2B, product_code=0x0001,
                        revision=(1, 7), serial=0x00A0_0001,
                        product_name="Cool Muscle 1 EtherNet/IP",
                        vendor_name="Myostat Motion Control Inc")


@dataclass(frozen=True, slots=True)
class AssemblyInfo:
    """One assembly instance (manual 3.1-3.3)."""

    instance: int
    size: int
    name: str
    writable: bool


INPUT_INSTANCE, OUTPUT_INSTANCE, CONFIG_INSTANCE = 0x65, 0x66, 0x80
ASSEMBLIES: dict[int, AssemblyInfo] = {
    INPUT_INSTANCE: AssemblyInfo(INPUT_INSTANCE, 8, "Input (T->O)", False),
    OUTPUT_INSTANCE: AssemblyInfo(OUTPUT_INSTANCE, 14, "Output (O->T)", True),
    CONFIG_INSTANCE: AssemblyInfo(CONFIG_INSTANCE, 0, "Configuration", True),
}


@dataclass(frozen=True, slots=True)
class ConnectionInfo:
    """The I/O connection the module offers (manual ch. 4; CIP Vol 1 3-5.5)."""

    name: str
    output: int
    input: int
    config: int
    rpi_min_us: int
    rpi_max_us: int
    rpi_default_us: int
    run_idle_header: bool     # O->T real-time format: 32-bit run/idle header


EXCLUSIVE_OWNER = ConnectionInfo("Exclusive Owner", OUTPUT_INSTANCE, INPUT_INSTANCE,
                                 CONFIG_INSTANCE, 2_000, 10_000_000, 10_000, True)

IDENTITY_CLASS, ROUTER_CLASS, ASSEMBLY_CLASS = 0x01, 0x02, 0x04
CONNECTION_MANAGER_CLASS, TCPIP_CLASS, ETHERNET_LINK_CLASS = 0x06, 0xF5, 0xF6
VENDOR_CLASS = 0x64
VENDOR_ATTRIBUTE = 0x64
CLASSES = (IDENTITY_CLASS, ROUTER_CLASS, ASSEMBLY_CLASS, CONNECTION_MANAGER_CLASS,
           VENDOR_CLASS, TCPIP_CLASS, ETHERNET_LINK_CLASS)
MAX_CONNECTIONS = 4


class Images(Protocol):
    """What the objects read and write of the module (:class:`.adapter.Cm1Module`)."""

    def input_image(self) -> bytes: ...

    def output_image(self) -> bytes: ...

    def write_output(self, data: bytes) -> None: ...

    def comm_error(self) -> int: ...

    def identity_status(self) -> int: ...


Getter = Callable[[], bytes]
Setter = Callable[[bytes], None]


@dataclass(frozen=True, slots=True)
class Attribute:
    getter: Getter
    setter: Setter | None = None
    in_all: bool = True


def _u16(v: int) -> Getter:
    return lambda: struct.pack("<H", v)


def _u32(v: int) -> Getter:
    return lambda: struct.pack("<I", v)


class ObjectModel:
    """Instances and attributes of every object, and the three attribute services."""

    def __init__(self, module: Images, *, host: str = "127.0.0.1",
                 output_owned: Callable[[], bool] = lambda: False,
                 reset: Callable[[], None] = lambda: None) -> None:
        self.module = module
        self.host = host
        self.output_owned = output_owned
        self.reset = reset
        self.table: dict[int, dict[int, dict[int, Attribute]]] = {}
        self._build()

    # -- building the tables ------------------------------------------------------------
    def _build(self) -> None:
        ident = IDENTITY
        self.table[IDENTITY_CLASS] = {0: self._class_attrs(1, 1), 1: {
            1: Attribute(_u16(ident.vendor_id)), 2: Attribute(_u16(ident.device_type)),
            3: Attribute(_u16(ident.product_code)), 4: Attribute(lambda: bytes(ident.revision)),
            5: Attribute(lambda: struct.pack("<H", self.module.identity_status())),
            6: Attribute(_u32(ident.serial)),
            7: Attribute(lambda: cip.short_string(ident.product_name))}}
        classes = struct.pack("<H", len(CLASSES)) + b"".join(struct.pack("<H", c) for c in CLASSES)
        self.table[ROUTER_CLASS] = {0: self._class_attrs(1, 1), 1: {
            1: Attribute(lambda: classes), 2: Attribute(_u16(MAX_CONNECTIONS))}}
        self.table[ASSEMBLY_CLASS] = {0: self._class_attrs(2, max(ASSEMBLIES)),
                                      **{i: self._assembly(a) for i, a in ASSEMBLIES.items()}}
        self.table[CONNECTION_MANAGER_CLASS] = {0: self._class_attrs(1, 1), 1: {}}
        self.table[VENDOR_CLASS] = {0: self._class_attrs(1, 1), 1: {
            VENDOR_ATTRIBUTE: Attribute(lambda: struct.pack("<H", self.module.comm_error()))}}
        self.table[TCPIP_CLASS] = {0: self._class_attrs(4, 1), 1: self._tcpip()}
        self.table[ETHERNET_LINK_CLASS] = {0: self._class_attrs(4, 1), 1: {
            1: Attribute(_u32(100)), 2: Attribute(_u32(0x0F)),
            3: Attribute(lambda: bytes((0x02, 0x00, 0xC0, 0x4D, 0x00, 0x01)))}}

    @staticmethod
    def _class_attrs(revision: int, max_instance: int) -> dict[int, Attribute]:
        return {1: Attribute(_u16(revision)), 2: Attribute(_u16(max_instance))}

    def _assembly(self, info: AssemblyInfo) -> dict[int, Attribute]:
        if info.instance == INPUT_INSTANCE:
            data = Attribute(self.module.input_image)
        elif info.instance == OUTPUT_INSTANCE:
            data = Attribute(self.module.output_image, self._set_output)
        else:
            data = Attribute(lambda: b"", self._set_config)
        return {3: data, 4: Attribute(_u16(info.size))}

    def _set_output(self, data: bytes) -> None:
        data = _without_route(data, ASSEMBLIES[OUTPUT_INSTANCE].size)
        _check_size(data, ASSEMBLIES[OUTPUT_INSTANCE].size)
        if self.output_owned():
            raise CipError(cip.DEVICE_STATE_CONFLICT)
        self.module.write_output(data)

    @staticmethod
    def _set_config(data: bytes) -> None:
        _check_size(_without_route(data, 0), 0)

    def _tcpip(self) -> dict[int, Attribute]:
        try:
            ip = int(ipaddress.IPv4Address(self.host))
        except ValueError:
            ip = 0
        path = struct.pack("<H", 2) + cip.encode_path(ETHERNET_LINK_CLASS, 1)
        config = struct.pack("<IIIII", ip, 0xFF000000 if ip >> 24 == 127 else 0xFFFFFF00,
                             0, 0, 0) + cip.cip_string("")
        return {1: Attribute(_u32(1)), 2: Attribute(_u32(0x04)), 3: Attribute(_u32(0x00)),
                4: Attribute(lambda: path), 5: Attribute(lambda: config),
                6: Attribute(lambda: cip.cip_string("coolmuscle-cm1"))}

    # -- services -----------------------------------------------------------------------
    def instance(self, request: cip.Request) -> dict[int, Attribute]:
        path = request.path
        if path.class_id is None or path.class_id not in self.table:
            raise CipError(cip.PATH_DESTINATION_UNKNOWN)
        instances = self.table[path.class_id]
        inst = 0 if path.instance is None else path.instance
        if inst not in instances:
            raise CipError(cip.PATH_DESTINATION_UNKNOWN)
        return instances[inst]

    def handle(self, request: cip.Request) -> bytes:
        """Reply data for an attribute service (raises :class:`CipError`)."""
        attrs = self.instance(request)
        service = request.service
        if service == cip.GET_ATTRIBUTE_SINGLE:
            return self._attribute(attrs, request).getter()
        if service == cip.SET_ATTRIBUTE_SINGLE:
            attr = self._attribute(attrs, request)
            if attr.setter is None:
                raise CipError(cip.ATTRIBUTE_NOT_SETTABLE)
            attr.setter(request.data)
            return b""
        path = request.path
        if service == cip.RESET and path.class_id == IDENTITY_CLASS and path.instance:
            return self._reset(request.data)
        if service == cip.GET_ATTRIBUTES_ALL and self._has_get_all(request):
            return b"".join(attrs[n].getter() for n in sorted(attrs) if attrs[n].in_all)
        raise CipError(cip.SERVICE_NOT_SUPPORTED)

    def _reset(self, data: bytes) -> bytes:
        """Identity Reset (CIP Vol 1 5A-2.3): type 0 or 1 restarts the module (its
        connections close, its outputs return to the power-up image); the motor, a
        separate device behind the serial line, is not reset."""
        kind = data[0] if data else 0
        if len(data) > 1:
            raise CipError(cip.TOO_MUCH_DATA)
        if kind not in (0, 1):
            raise CipError(cip.INVALID_PARAMETER)
        self.reset()
        return b""

    @staticmethod
    def _attribute(attrs: dict[int, Attribute], request: cip.Request) -> Attribute:
        number = request.path.attribute
        if number is None or number not in attrs:
            raise CipError(cip.ATTRIBUTE_NOT_SUPPORTED)
        return attrs[number]

    @staticmethod
    def _has_get_all(request: cip.Request) -> bool:
        """Get_Attributes_All where the object defines it (not the Assembly, CM, vendor)."""
        return request.path.class_id in (IDENTITY_CLASS, ROUTER_CLASS, TCPIP_CLASS,
                                         ETHERNET_LINK_CLASS)


#: The empty route path (size 0, pad) pycomm3 puts after the data of an unconnected
#: request unless told ``route_path=False``.
EMPTY_ROUTE = b"\x00\x00"


def _without_route(data: bytes, size: int) -> bytes:
    """``data`` without a trailing empty route path when exactly that follows ``size`` bytes."""
    if len(data) == size + len(EMPTY_ROUTE) and data[size:] == EMPTY_ROUTE:
        return data[:size]
    return data


def _check_size(data: bytes, size: int) -> None:
    if len(data) < size:
        raise CipError(cip.NOT_ENOUGH_DATA)
    if len(data) > size:
        raise CipError(cip.TOO_MUCH_DATA)
