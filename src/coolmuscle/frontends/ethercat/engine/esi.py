"""The ESI file (EtherCAT Slave Information, ETG.2000) of the bridge, from the object table.

``coolmuscle ethercat esi > CoolMuscleBridge.xml`` (manual 8.1.4 "Install ESI
File").  Vendor, one Device per variant (EB01, EB02, EB12) with its identity, the
dictionary (data types and the available objects with defaults and access), the
FMMUs and SyncManagers of manual 2.3, the fixed PDOs of 6.3.3, the CoE mailbox
(SDO information and complete access; PDO assignment and configuration are fixed)
and the EEPROM configuration area.  The element order follows the ETG.2000
EtherCATInfo schema.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from ..bridge import identity as ident
from ..bridge.table import STRING, VAR, Entry, Obj, Table, build_table
from .sii import COE_DETAILS, EEPROM_BYTES, build_sii

ESI_VERSION = "1.6"


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


def _device(devices: ET.Element, table: Table) -> None:
    v = table.variant
    device = _sub(devices, "Device", Physics="YY")
    _sub(device, "Type", v.code, ProductCode=_hex(v.product_code), RevisionNo=_hex(ident.REVISION))
    _sub(device, "Name", v.device_name, LcId="1033")
    _sub(device, "GroupType", "CoolMuscle")
    profile = _sub(device, "Profile")
    _sub(profile, "ProfileNo", "402")
    _sub(profile, "AddInfo", "2")
    _sub(profile, "ChannelCount", str(ident.AXES))
    dictionary = _sub(profile, "Dictionary")
    objects = table.available()
    _datatypes(dictionary, objects)
    _objects(dictionary, objects)
    for kind in ("Outputs", "Inputs", "MBoxState"):
        _sub(device, "Fmmu", kind)
    out_len = table.image_bytes(table.rx_pdos())
    in_len = table.image_bytes(table.tx_pdos())
    for start, size, control, kind in (
            (ident.MBX_OUT_START, ident.MBX_OUT_SIZE, ident.SM_CONTROL[0], "MBoxOut"),
            (ident.MBX_IN_START, ident.MBX_IN_SIZE, ident.SM_CONTROL[1], "MBoxIn"),
            (ident.PD_OUT_START, out_len, ident.SM_CONTROL[2], "Outputs"),
            (ident.PD_IN_START, in_len, ident.SM_CONTROL[3], "Inputs")):
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
    _sub(eeprom, "ConfigData", build_sii(table)[:14].hex().upper())


def build_esi(bridges: tuple[str, ...] = tuple(ident.VARIANTS)) -> "ET.ElementTree[ET.Element]":
    """The EtherCATInfo tree with one Device per bridge variant."""
    root = ET.Element("EtherCATInfo", {
        "xmlns:xsi": "http://www.w3.org/2001/XMLSchema-instance",
        "xsi:noNamespaceSchemaLocation": "EtherCATInfo.xsd", "Version": ESI_VERSION})
    vendor = _sub(root, "Vendor")
    _sub(vendor, "Id", _hex(ident.VENDOR_ID))
    _sub(vendor, "Name", ident.VENDOR_NAME)
    descriptions = _sub(root, "Descriptions")
    groups = _sub(descriptions, "Groups")
    group = _sub(groups, "Group")
    _sub(group, "Type", "CoolMuscle")
    _sub(group, "Name", "Cool Muscle")
    devices = _sub(descriptions, "Devices")
    for code in bridges:
        _device(devices, build_table(code))
    tree: ET.ElementTree[ET.Element] = ET.ElementTree(root)
    ET.indent(tree, space="  ")
    return tree


def esi_text(bridges: tuple[str, ...] = tuple(ident.VARIANTS)) -> str:
    """The ESI file as text (UTF-8 XML declaration included)."""
    body: str = ET.tostring(build_esi(bridges).getroot(), encoding="unicode")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + body + "\n"


__all__ = ["build_esi", "esi_text"]
