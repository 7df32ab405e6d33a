"""The ESI file, the SII image and the dictionary come from one table and agree.

Manual 2.3 (SM/FMMU layout), 6.3.3 (PDO mapping), 8.1.4 (the ESI file), Appendix 6.
No ETG.2000 schema file is available offline; the test checks the element order of
the EtherCATInfo schema's Device sequence and the required elements instead.
"""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET

import pytest

from coolmuscle.frontends.ethercat.bridge import identity as ident
from coolmuscle.frontends.ethercat.bridge.description import describe
from coolmuscle.frontends.ethercat.bridge.esi import esi_text
from coolmuscle.frontends.ethercat.bridge.table import build_table
from coolmuscle.frontends.ethercat.engine.dictionary import NO_OBJECT, Dictionary, SdoAbort
from coolmuscle.frontends.ethercat.engine.od import VAR
from coolmuscle.frontends.ethercat.engine.sii import build_sii, crc8, parse

#: ETG.2000 EtherCATInfo DeviceType: the order of its child elements.
DEVICE_ORDER = ["Type", "HideType", "AlternativeType", "SubDevice", "Name", "Comment", "URL",
                "Info", "GroupType", "Profile", "Fmmu", "Sm", "Su", "RxPdo", "TxPdo",
                "Mailbox", "Dc", "Slots", "ESC", "Eeprom", "Image"]


def num(text: str) -> int:
    return int(text[2:], 16) if text.startswith("#x") else int(text)


@pytest.fixture(scope="module")
def esi() -> ET.Element:
    return ET.fromstring(esi_text().split("\n", 1)[1])


def devices(root: ET.Element) -> dict[str, ET.Element]:
    return {d.findtext("Type"): d for d in root.iter("Device")}


def test_esi_is_etg2000_shaped(esi):
    assert esi.tag == "EtherCATInfo" and num(esi.findtext("Vendor/Id")) == ident.VENDOR_ID
    assert set(devices(esi)) == {"EB01", "EB02", "EB12"}
    for device in esi.iter("Device"):
        tags = [child.tag for child in device]
        ranks = [DEVICE_ORDER.index(t) for t in tags]
        assert ranks == sorted(ranks), tags
        for required in ("Type", "Name", "GroupType", "Profile", "Sm", "Mailbox", "Eeprom"):
            assert device.find(required) is not None
    groups = {g.findtext("Type") for g in esi.iter("Group")}
    assert {d.findtext("GroupType") for d in esi.iter("Device")} <= groups


@pytest.mark.parametrize("code", ["EB01", "EB02", "EB12"])
def test_esi_agrees_with_the_sii_image_and_the_dictionary(esi, code):
    slave = describe(code)
    image = build_sii(slave)
    sii = parse(image)
    od = Dictionary(slave.table)
    device = devices(esi)[code]
    assert sii.crc_ok and crc8(image[:14]) == image[14]
    kind = device.find("Type")
    assert (num(kind.get("ProductCode")), num(kind.get("RevisionNo"))) == (sii.product,
                                                                           sii.revision)
    assert sii.vendor == num(esi.findtext("Vendor/Id"))
    assert device.findtext("Name") == sii.name == od.get(0x1008, 0)
    assert (sii.vendor, sii.product, sii.revision, sii.serial) == tuple(
        od.get(0x1018, s) for s in range(1, 5))
    assert bytes.fromhex(device.findtext("Eeprom/ConfigData")) == image[:14]
    # SyncManagers: ESI Sm elements = SII category 41 (manual 2.3)
    esi_sms = [(num(s.get("StartAddress")), int(s.get("DefaultSize")), num(s.get("ControlByte")))
               for s in device.findall("Sm")]
    assert esi_sms == [(start, length, control) for start, length, control, _e, _k in sii.sms]
    assert [k for *_rest, k in sii.sms] == [1, 2, 3, 4]
    assert sii.mailbox == (esi_sms[0][0], esi_sms[0][1], esi_sms[1][0], esi_sms[1][1])
    assert [f.text for f in device.findall("Fmmu")] == ["Outputs", "Inputs", "MBoxState"]
    assert sii.fmmu == [1, 2, 3]
    # PDOs: ESI = SII categories 50/51 = the dictionary's mapping objects (6.3.3)
    for tag, sii_pdos, assign in (("RxPdo", sii.rxpdo, 0x1C12), ("TxPdo", sii.txpdo, 0x1C13)):
        esi_pdos = [(num(p.findtext("Index")),
                     [(num(e.findtext("Index")), int(e.findtext("SubIndex")),
                       int(e.findtext("BitLen"))) for e in p.findall("Entry")])
                    for p in device.findall(tag)]
        assert esi_pdos == sii_pdos
        assert [i for i, _e in esi_pdos] == [od.get(assign, s) for s in range(1, 5)]
        for index, entries in esi_pdos:
            assert [(e[0] << 16) | (e[1] << 8) | e[2] for e in entries] == \
                [od.get(index, s) for s in range(1, od.get(index, 0) + 1)]
    assert sum(b for _i, es in sii.rxpdo for *_x, b in es) // 8 == od.output_size == 24
    assert sum(b for _i, es in sii.txpdo for *_x, b in es) // 8 == od.input_size == 24
    # Objects: ESI dictionary = the available objects, with their defaults
    objects = {num(o.findtext("Index")): o for o in device.iter("Object")}
    assert sorted(objects) == [o.index for o in od.objects()]
    for obj in od.objects():
        el = objects[obj.index]
        assert el.findtext("Name") == obj.name
        if obj.code == VAR:
            entry = obj.entries[0]
            assert bytes.fromhex(el.findtext("Info/DefaultData")) == od.read(obj.index, 0)
            assert el.findtext("Flags/Access") == entry.access
    coe = device.find("Mailbox/CoE")
    assert coe.get("SdoInfo") == "true" and coe.get("CompleteAccess") == "true"


def test_the_eb12_bridge_has_cm1_on_id1_2_and_cm2_on_id3_4_1_4_3():
    od = Dictionary(build_table("EB12"))
    assert [od.get(0xF511 + i, 1) for i in range(4)] == [1, 1, 2, 2]
    assert od.lookup(0x60FB + 0x800 * 2, 1)                   # servo stiffness: CM2 only
    with pytest.raises(SdoAbort) as refused:
        od.lookup(0x60FB, 1)
    assert refused.value.code == NO_OBJECT
    assert struct.unpack("<I", od.read(0x1018, 2))[0] == 0x00EB0012


def test_an_eb12_chain_has_one_firmware_per_motor_1_4_3():
    from coolmuscle.chain import Chain
    from coolmuscle.tools.cli.ethercat import chain_firmware
    chain = Chain(None, 4, firmware=chain_firmware("EB12"))
    try:
        assert [m.firmware.name for m in chain.motors.values()] == ["cm1", "cm1", "cm2", "cm2"]
    finally:
        chain.close()


def test_an_entrys_place_reads_and_writes_what_sdo_and_the_process_images_see_6_3_1():
    """An application keeps an entry's place (Dictionary.key) and reads and writes the
    value there every cycle: the same value SDO reads and the TxPDO image carries, and
    what an RxPDO image brings; an entry the slave lacks has no place."""
    od = Dictionary(build_table("EB02"))
    statusword, controlword = od.key(0x6041), od.key(0x6040)
    od.set_at(statusword, 0x1237)
    assert od.get(0x6041) == 0x1237 == od.value_at(statusword)
    assert struct.unpack("<H", od.read(0x6041, 0))[0] == 0x1237
    od.write(0x6040, 0, struct.pack("<H", 0x000F))             # SDO download
    assert od.value_at(controlword) == 0x000F
    od.unpack_outputs(b"\x06\x00" + bytes(od.output_size - 2))  # 6040h first (RxPDO)
    assert od.value_at(controlword) == 6
    assert od.pack_inputs()[:2] == struct.pack("<H", 0x1237)   # 6041h first (TxPDO)
    with pytest.raises(KeyError):
        od.key(0x60FB, 9)
    od.set(0x5FFF, 3, 42)                                       # an application's own entry
    assert od.get(0x5FFF, 3) == 42 == od.value_at(od.key(0x5FFF, 3))
