"""The CIP object service: instances and attributes, and the services that read and write them.

A product module builds its objects as a table (class -> instance -> attribute ->
:class:`Attribute`, instance 0 holding the class attributes) with the builders of the
standard objects here: Identity (0x01, CIP Vol 1 5A-2), Message Router (0x02, 5A-3),
TCP/IP Interface (0xF5, Vol 2 5-3, with its settable encapsulation inactivity
timeout) and Ethernet Link (0xF6, Vol 2 5-4); the Assembly
(0x04) data and any vendor class are the product's.  :class:`ObjectService` serves
Get_Attribute_Single, Set_Attribute_Single, Get_Attributes_All and the Identity's
Reset over such a table, raising :class:`~.messages.CipError` for every refusal.

Refusals (CIP Vol 1 appendix B; docs/fidelity.md "EtherNet/IP"): an unknown class or
instance is 0x05 (path destination unknown, as ODVA's OpENer answers), a service the
object lacks 0x08 (Identity also has Reset), an attribute it lacks 0x14, a read-only
attribute 0x0E.  The Get services ignore request data after the path (as OpENer
does; pycomm3 sends its route path there by default).  :func:`exact_data` is the rule
for a Set of fixed-size data (an assembly): its exact size, or its size followed by
exactly the empty route path (``00 00``); short and long data are 0x13 and 0x15.
"""

from __future__ import annotations

import ipaddress
import struct
from collections.abc import Callable
from dataclasses import dataclass

from . import messages as cip
from .description import IdentityInfo
from .messages import CipError

IDENTITY_CLASS, ROUTER_CLASS, ASSEMBLY_CLASS = 0x01, 0x02, 0x04
CONNECTION_MANAGER_CLASS, TCPIP_CLASS, ETHERNET_LINK_CLASS = 0x06, 0xF5, 0xF6
#: The classes whose objects define Get_Attributes_All (not the Assembly, the
#: Connection Manager or a vendor class).
GET_ALL_CLASSES = frozenset({IDENTITY_CLASS, ROUTER_CLASS, TCPIP_CLASS, ETHERNET_LINK_CLASS})

Getter = Callable[[], bytes]
Setter = Callable[[bytes], None]


@dataclass(frozen=True, slots=True)
class Attribute:
    getter: Getter
    setter: Setter | None = None
    in_all: bool = True


Instance = dict[int, Attribute]
#: class -> instance (0: the class attributes) -> the instance's attributes.
ObjectTable = dict[int, dict[int, Instance]]


def u16(v: int) -> Getter:
    return lambda: struct.pack("<H", v)


def u32(v: int) -> Getter:
    return lambda: struct.pack("<I", v)


def class_attributes(revision: int, max_instance: int) -> Instance:
    """Class attributes 1 (revision) and 2 (max instance)."""
    return {1: Attribute(u16(revision)), 2: Attribute(u16(max_instance))}


def identity_instance(ident: IdentityInfo, status: Callable[[], int]) -> Instance:
    """Identity instance 1, attributes 1-7 (CIP Vol 1 5A-2.2); ``status`` is attribute 5."""
    return {
        1: Attribute(u16(ident.vendor_id)), 2: Attribute(u16(ident.device_type)),
        3: Attribute(u16(ident.product_code)), 4: Attribute(lambda: bytes(ident.revision)),
        5: Attribute(lambda: struct.pack("<H", status())),
        6: Attribute(u32(ident.serial)),
        7: Attribute(lambda: cip.short_string(ident.product_name))}


def router_instance(classes: tuple[int, ...], max_connections: int) -> Instance:
    """Message Router instance 1: the object list and the connections it takes (5A-3.3
    attribute 2, "number available": its own, the class 3 connections)."""
    listed = struct.pack("<H", len(classes)) + b"".join(struct.pack("<H", c) for c in classes)
    return {1: Attribute(lambda: listed), 2: Attribute(u16(max_connections))}


#: TCP/IP Interface attribute 13 (CIP Vol 2 5-3): its default and largest value (s).
INACTIVITY_DEFAULT_S = 120
INACTIVITY_MAX_S = 3600


@dataclass(slots=True)
class EncapsulationTimeout:
    """TCP/IP Interface attribute 13, Encapsulation Inactivity Timeout (CIP Vol 2 5-3,
    UINT seconds): a TCP connection that carries no encapsulation packet
    for that long is closed by the adapter; 0 disables it.  Get and Set; a value above
    3600 is 0x09 (invalid attribute value), as OpENer answers; the out-of-box value is
    120 (Identity Reset type 1 restores it)."""

    seconds: int = INACTIVITY_DEFAULT_S

    def get(self) -> bytes:
        return struct.pack("<H", self.seconds)

    def set(self, data: bytes) -> None:
        value = struct.unpack("<H", exact_data(data, 2))[0]
        if value > INACTIVITY_MAX_S:
            raise CipError(cip.INVALID_ATTRIBUTE_VALUE)
        self.seconds = value

    def out_of_box(self) -> None:
        self.seconds = INACTIVITY_DEFAULT_S


def tcpip_instance(host: str, hostname: str, inactivity: EncapsulationTimeout) -> Instance:
    """TCP/IP Interface instance 1: status, capability, control, the physical link
    (Ethernet Link instance 1), the configuration of ``host``, the host name, and the
    encapsulation inactivity timeout (13; Get_Attributes_All keeps to 1-6, as before)."""
    try:
        ip = int(ipaddress.IPv4Address(host))
    except ValueError:
        ip = 0
    path = struct.pack("<H", 2) + cip.encode_path(ETHERNET_LINK_CLASS, 1)
    config = struct.pack("<IIIII", ip, 0xFF000000 if ip >> 24 == 127 else 0xFFFFFF00,
                         0, 0, 0) + cip.cip_string("")
    return {1: Attribute(u32(1)), 2: Attribute(u32(0x04)), 3: Attribute(u32(0x00)),
            4: Attribute(lambda: path), 5: Attribute(lambda: config),
            6: Attribute(lambda: cip.cip_string(hostname)),
            13: Attribute(inactivity.get, inactivity.set, in_all=False)}


def ethernet_link_instance(speed_mbps: int, flags: int, mac: bytes) -> Instance:
    """Ethernet Link instance 1: interface speed, flags, physical address."""
    return {1: Attribute(u32(speed_mbps)), 2: Attribute(u32(flags)),
            3: Attribute(lambda: mac)}


#: The empty route path (size 0, pad) pycomm3 puts after the data of an unconnected
#: request unless told ``route_path=False``.
EMPTY_ROUTE = b"\x00\x00"


def exact_data(data: bytes, size: int) -> bytes:
    """``data`` of a Set that must be ``size`` bytes: a trailing empty route path after
    exactly ``size`` bytes is dropped; anything shorter or longer is refused."""
    if len(data) == size + len(EMPTY_ROUTE) and data[size:] == EMPTY_ROUTE:
        data = data[:size]
    if len(data) < size:
        raise CipError(cip.NOT_ENOUGH_DATA)
    if len(data) > size:
        raise CipError(cip.TOO_MUCH_DATA)
    return data


class ObjectService:
    """The attribute services and the Identity's Reset over one object table."""

    def __init__(self, table: ObjectTable, *, reset: Callable[[], None] = lambda: None,
                 out_of_box: Callable[[], None] = lambda: None,
                 get_all: frozenset[int] = GET_ALL_CLASSES) -> None:
        self.table = table
        self.reset = reset
        self.out_of_box = out_of_box
        self.get_all = get_all

    def instance(self, request: cip.Request) -> Instance:
        path = request.path
        if path.class_id is None or path.class_id not in self.table:
            raise CipError(cip.PATH_DESTINATION_UNKNOWN)
        instances = self.table[path.class_id]
        inst = 0 if path.instance is None else path.instance
        if inst not in instances:
            raise CipError(cip.PATH_DESTINATION_UNKNOWN)
        return instances[inst]

    def get(self, class_id: int, instance: int, attribute: int) -> bytes:
        """One attribute's value, read by the adapter itself (ListIdentity's item)."""
        return self.table[class_id][instance][attribute].getter()

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
        if service == cip.GET_ATTRIBUTES_ALL and request.path.class_id in self.get_all:
            return b"".join(attrs[n].getter() for n in sorted(attrs) if attrs[n].in_all)
        raise CipError(cip.SERVICE_NOT_SUPPORTED)

    def _reset(self, data: bytes) -> bytes:
        """Identity Reset (CIP Vol 1 5A-2.3): type 0 or 1 restarts the adapter (what that
        means is the product's ``reset``); type 1 first restores the out-of-box settings
        (``out_of_box``)."""
        kind = data[0] if data else 0
        if len(data) > 1:
            raise CipError(cip.TOO_MUCH_DATA)
        if kind not in (0, 1):
            raise CipError(cip.INVALID_PARAMETER)
        if kind == 1:
            self.out_of_box()
        self.reset()
        return b""

    @staticmethod
    def _attribute(attrs: Instance, request: cip.Request) -> Attribute:
        number = request.path.attribute
        if number is None or number not in attrs:
            raise CipError(cip.ATTRIBUTE_NOT_SUPPORTED)
        return attrs[number]
