"""The ESI file (EtherCAT Slave Information, ETG.2000) of slaves, from their descriptions.

Vendor, the groups, one Device per :class:`~.description.SlaveDescription` with its
identity, profile, the dictionary (data types and the available objects with defaults
and access), the FMMUs and SyncManagers, the fixed PDOs of the PDO assignment, the CoE
mailbox (SDO information and complete access; PDO assignment and configuration are
fixed) and the EEPROM configuration area (the first 14 bytes of the SII image).  The
element order follows the ETG.2000 EtherCATInfo schema.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence

from .description import SlaveDescription
from .od import STRING, VAR, Entry, Obj, Table
from .sii import COE_DETAILS, EEPROM_BYTES, build_sii

ESI_VERSION = "1.6"
#: ESI ``Sm`` element text of SM0-SM3.
SM_KINDS = ("MBoxOut", "MBoxIn", "Outputs", "Inputs")


def _hex(value: int, digits: int = 8) -> str:
    return f"#x{value:0{digits}X}"


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrs: str) -> ET.Element:
    el = ET.SubElement(parent, tag, attrs)
    if text is not None:
        el.text = text
    return el


def _type_name(entry: Entry) -> str:
    if entry.dtype is STRING:
        return f"STRING({max(1, entry.bits // 8)})"
    return entry.dtype.name


def _access(entry: Entry) -> str:
    return entry.access


def _default(entry: Entry) -> str:
    value = entry.default
    if entry.dtype is STRING:
        return str(value).encode("latin-1").hex().upper()
    return entry.dtype.encode(value).hex().upper()


def _flags(parent: ET.Element, entry: Entry) -> None:
    flags = _sub(parent, "Flags")
    _sub(flags, "Access", _access(entry))
    if entry.pdo:
        _sub(flags, "PdoMapping", "R" if entry.pdo == "rx" else "T")


def _dt_name(obj: Obj) -> str:
    return f"DT{obj.index:04X}"


def _record_bits(obj: Obj) -> int:
    bits = 0
    for e in obj.entries:
        bits += e.bits + (8 if e.sub == 0 else 0)
    return bits


def _datatypes(parent: ET.Element, objects: list[Obj]) -> None:
    types = _sub(parent, "DataTypes")
    basics: dict[str, int] = {}
    for obj in objects:
        for e in obj.entries:
            basics.setdefault(_type_name(e), e.bits)
    for name, bits in sorted(basics.items()):
        dt = _sub(types, "DataType")
        _sub(dt, "Name", name)
        _sub(dt, "BitSize", str(bits))
    for obj in objects:
        if obj.code == VAR:
            continue
        dt = _sub(types, "DataType")
        _sub(dt, "Name", _dt_name(obj))
        _sub(dt, "BitSize", str(_record_bits(obj)))
        offset = 0
        for e in obj.entries:
            if e.available:
                item = _sub(dt, "SubItem")
                _sub(item, "SubIdx", str(e.sub))
                _sub(item, "Name", "SubIndex 000" if e.sub == 0 else e.name)
                _sub(item, "Type", _type_name(e))
                _sub(item, "BitSize", str(e.bits))
                _sub(item, "BitOffs", str(offset))
                _flags(item, e)
            offset += e.bits + (8 if e.sub == 0 else 0)


def _objects(parent: ET.Element, objects: list[Obj]) -> None:
    objs = _sub(parent, "Objects")
    for obj in objects:
        el = _sub(objs, "Object")
        _sub(el, "Index", _hex(obj.index, 4))
        _sub(el, "Name", obj.name)
        if obj.code == VAR:
            entry = obj.entries[0]
            _sub(el, "Type", _type_name(entry))
            _sub(el, "BitSize", str(entry.bits))
            info = _sub(el, "Info")
            _sub(info, "DefaultData", _default(entry))
            _flags(el, entry)
            continue
        _sub(el, "Type", _dt_name(obj))
        _sub(el, "BitSize", str(_record_bits(obj)))
        info = _sub(el, "Info")
        for e in obj.entries:
            if not e.available:
                continue
            item = _sub(info, "SubItem")
            _sub(item, "Name", "SubIndex 000" if e.sub == 0 else e.name)
            sinfo = _sub(item, "Info")
            _sub(sinfo, "DefaultData", _default(e))
        flags = _sub(el, "Flags")
        _sub(flags, "Access", "ro")


def _pdos(device: ET.Element, table: Table, tag: str, pdos: list[Obj], sm: int) -> None:
    for pdo in pdos:
        el = _sub(device, tag, Fixed="1", Mandatory="1", Sm=str(sm))
        _sub(el, "Index", _hex(pdo.index, 4))
        _sub(el, "Name", pdo.name)
        for obj, entry in table.pdo_entries(pdo):
            item = _sub(el, "Entry")
            _sub(item, "Index", _hex(obj.index, 4))
            _sub(item, "SubIndex", str(entry.sub))
            _sub(item, "BitLen", str(entry.bits))
            _sub(item, "Name", obj.name if obj.code == VAR else entry.name)
            _sub(item, "DataType", entry.dtype.name)


def _device(devices: ET.Element, slave: SlaveDescription) -> None:
    table, names = slave.table, slave.names
    device = _sub(devices, "Device", Physics="YY")
    _sub(device, "Type", names.order, ProductCode=_hex(slave.identity.product_code),
         RevisionNo=_hex(slave.identity.revision))
    _sub(device, "Name", names.device, LcId="1033")
    _sub(device, "GroupType", names.group_type)
    profile = _sub(device, "Profile")
    _sub(profile, "ProfileNo", str(slave.profile))
    _sub(profile, "AddInfo", str(slave.profile_info))
    _sub(profile, "ChannelCount", str(slave.channels))
    dictionary = _sub(profile, "Dictionary")
    objects = table.available()
    _datatypes(dictionary, objects)
    _objects(dictionary, objects)
    for kind in ("Outputs", "Inputs", "MBoxState"):
        _sub(device, "Fmmu", kind)
    for (start, size, control), kind in zip(slave.sync_managers(), SM_KINDS):
        _sub(device, "Sm", kind, DefaultSize=str(size), StartAddress=_hex(start, 4),
             ControlByte=_hex(control, 2), Enable="1")
    _pdos(device, table, "RxPdo", table.rx_pdos(), 2)
    _pdos(device, table, "TxPdo", table.tx_pdos(), 3)
    mailbox = _sub(device, "Mailbox", DataLinkLayer="true")
    _sub(mailbox, "CoE", SdoInfo="true" if COE_DETAILS & 0x02 else "false",
         CompleteAccess="true" if COE_DETAILS & 0x20 else "false",
         PdoAssign="false", PdoConfig="false")
    eeprom = _sub(device, "Eeprom")
    _sub(eeprom, "ByteSize", str(EEPROM_BYTES))
    _sub(eeprom, "ConfigData", build_sii(slave)[:14].hex().upper())


def build_esi(slaves: Sequence[SlaveDescription]) -> ET.ElementTree[ET.Element]:
    """The EtherCATInfo tree with one Device per description (one vendor for all)."""
    if not slaves:
        raise ValueError("an ESI file describes at least one device")
    vendors = {(s.identity.vendor_id, s.names.vendor) for s in slaves}
    if len(vendors) > 1:
        raise ValueError(f"one ESI file has one vendor, not {sorted(vendors)}")
    root = ET.Element("EtherCATInfo", {
        "xmlns:xsi": "http://www.w3.org/2001/XMLSchema-instance",
        "xsi:noNamespaceSchemaLocation": "EtherCATInfo.xsd", "Version": ESI_VERSION})
    vendor = _sub(root, "Vendor")
    _sub(vendor, "Id", _hex(slaves[0].identity.vendor_id))
    _sub(vendor, "Name", slaves[0].names.vendor)
    descriptions = _sub(root, "Descriptions")
    groups = _sub(descriptions, "Groups")
    for group_type, name in dict.fromkeys((s.names.group_type, s.names.group) for s in slaves):
        group = _sub(groups, "Group")
        _sub(group, "Type", group_type)
        _sub(group, "Name", name)
    devices = _sub(descriptions, "Devices")
    for slave in slaves:
        _device(devices, slave)
    tree: ET.ElementTree[ET.Element] = ET.ElementTree(root)
    ET.indent(tree, space="  ")
    return tree


def esi_text(slaves: Sequence[SlaveDescription]) -> str:
    """The ESI file as text (UTF-8 XML declaration included)."""
    body: str = ET.tostring(build_esi(slaves).getroot(), encoding="unicode")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + body + "\n"


__all__ = ["build_esi", "esi_text"]
