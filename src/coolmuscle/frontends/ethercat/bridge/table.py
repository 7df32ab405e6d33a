"""The one object table of the bridge (ethercat-bridge-users-guide.txt Appendix 6).

Every object of the manual's object list is here with index, subindex, name, data
type, access, PDO mappability, default, range, availability (N/A objects are listed
and marked, so the dictionary answers 06020000h / 06090011h for them) and the
manual section that defines it, in the engine's object-dictionary types
(:mod:`..engine.od`).  The table goes to the engine inside the bridge's slave
description (:mod:`.description`): the object dictionary, the SII image and the ESI
file are all produced from it, so they cannot disagree.

The communication objects get their values here; the drive objects (6000h-7FFFh,
F000h-F594h) carry the manual's metadata and defaults, and their behaviour is
attached by the bridge application through
:class:`~..engine.dictionary.Dictionary` hooks (:mod:`.bridge_objects`).  Axis n's
objects are those of ID1 plus 0x800 x (n-1) (Appendix 6 "The offset of object of ID2
against ID1 is 0x800").
"""

from __future__ import annotations

from dataclasses import replace

from ..engine import od
from ..engine.od import (
    ARRAY,
    BOOL,
    INT8,
    INT16,
    INT32,
    STRING,
    UINT8,
    UINT16,
    UINT32,
    DataType,
    Entry,
    Obj,
    Table,
)
from . import identity as ident

#: Where an object's section is not given, it is the manual's object list.
APPENDIX_6 = "Appendix 6"


def var(index: int, name: str, dtype: DataType, access: str = "ro", default: int | str = 0,
        *, pdo: str = "", available: bool = True, section: str = APPENDIX_6,
        max_len: int = 0) -> Obj:
    """:func:`..engine.od.var`, defined in Appendix 6 unless ``section`` says otherwise."""
    return od.var(index, name, dtype, access, default, pdo=pdo, available=available,
                  section=section, max_len=max_len)


def record(index: int, name: str, subs: list[Entry], *, code: int = od.RECORD,
           section: str = APPENDIX_6, available: bool = True,
           count_type: DataType = UINT8, count: int | None = None) -> Obj:
    """:func:`..engine.od.record`, defined in Appendix 6 unless ``section`` says otherwise."""
    return od.record(index, name, subs, code=code, section=section, available=available,
                     count_type=count_type, count=count)


# -- the communication area (1000h-1FFFh) -------------------------------------
def _communication(v: ident.Variant) -> list[Obj]:
    objs = [
        var(0x1000, "Device type", UINT32, default=0x00040192, section="Appendix 6"),
        var(0x1001, "Error register", UINT8, default=0, section="Appendix 6"),
        var(0x1008, "Manufacturer device name", STRING, default=v.device_name),
        var(0x1009, "Manufacturer hardware version", STRING, default=ident.HARDWARE_VERSION),
        var(0x100A, "Manufacturer software version", STRING, default=ident.SOFTWARE_VERSION),
        record(0x1018, "Identity", [
            Entry(1, "Vendor ID", UINT32, default=ident.VENDOR_ID),
            Entry(2, "Product code", UINT32, default=v.product_code),
            Entry(3, "Revision", UINT32, default=ident.REVISION),
            Entry(4, "Serial number", UINT32, default=ident.SERIAL)]),
        record(0x10F1, "Error settings", [
            Entry(1, "Local error reaction", UINT32, "rw", default=0),
            Entry(2, "Sync error counter limit", UINT32, "rw", default=4)]),
    ]
    for axis in range(ident.AXES):
        n, d = axis + 1, 0x800 * axis
        rx, tx = 0x1600 + 0x10 * axis, 0x1A00 + 0x10 * axis
        objs += [
            od.mapping(rx, f"ID{n} csp/csv RxPDO mapping",
                     [(0x6040 + d, 0, 16), (0x6060 + d, 0, 8), (0x607A + d, 0, 32),
                      (0x60FF + d, 0, 32)], False, "Appendix 6"),
            od.mapping(rx + 1, f"ID{n} csp RxPDO mapping",
                     [(0x6040 + d, 0, 16), (0x607A + d, 0, 32)], True, "6.3.3"),
            od.mapping(rx + 2, f"ID{n} csv RxPDO mapping",
                     [(0x6040 + d, 0, 16), (0x60FF + d, 0, 32)], False, "Appendix 6"),
            od.mapping(tx, f"ID{n} csp/csv TxPDO mapping",
                     [(0x6041 + d, 0, 16), (0x6061 + d, 0, 8), (0x6064 + d, 0, 32),
                      (0x606C + d, 0, 32)], False, "Appendix 6"),
            od.mapping(tx + 1, f"ID{n} csp TxPDO mapping",
                     [(0x6041 + d, 0, 16), (0x6064 + d, 0, 32)], True, "6.3.3"),
            od.mapping(tx + 2, f"ID{n} csv TxPDO mapping",
                     [(0x6041 + d, 0, 16), (0x606C + d, 0, 32)], False, "Appendix 6"),
        ]
    objs.append(record(0x1C00, "Sync manager communication type", [
        Entry(i + 1, name, UINT8, default=i + 1) for i, name in enumerate(
            ("Mailbox out", "Mailbox in", "Process data out", "Process data in"))],
        code=ARRAY, section="Appendix 6"))
    for index, base, sm in ((0x1C12, 0x1601, 2), (0x1C13, 0x1A01, 3)):
        objs.append(record(index, f"Sync manager {sm} PDO assignment", [
            Entry(i + 1, f"ID{i + 1} csp {'Rx' if sm == 2 else 'Tx'}PDO", UINT16, "rw",
                  default=base + 0x10 * i) for i in range(ident.AXES)],
            code=ARRAY, section="6.3.3"))
    for index, sm in ((0x1C32, 2), (0x1C33, 3)):
        objs.append(record(index, f"Sync manager {sm} synchronization", [
            Entry(1, "Synchronization type", UINT16, "rw", default=0, low=0, high=1),
            Entry(2, "Cycle time", UINT32, default=ident.CYCLE_NS),
            Entry(4, "Synchronization types supported", UINT16, default=0x0003),
            Entry(5, "Minimum cycle time", UINT32, default=ident.CYCLE_NS),
            Entry(6, "Calc and copy time", UINT32, default=0),
            Entry(8, "Get cycle time", UINT16, "rw", available=False),
            Entry(9, "Delay time", UINT32, available=False),
            Entry(0x0A, "Sync0 cycle time", UINT32, "rw", available=False),
            Entry(0x0B, "SM-event missed", UINT16, available=False),
            Entry(0x0C, "Cycle time too small", UINT16, available=False),
            Entry(0x20, "Sync error", BOOL, available=False)]))
    return objs


# -- per axis (6000h-7FFFh), manual 6.1-6.5 and Appendix 6 ------------------------
_AXIS_VARS: tuple[tuple[int, str, DataType, str, str, bool, str, int], ...] = (
    # index, name, type, access, pdo, available, section, default
    (0x603F, "Error code", UINT16, "ro", "", False, "Appendix 6", 0),
    (0x6040, "Controlword", UINT16, "rw", "rx", True, "6.1.2", 0),
    (0x6041, "Statusword", UINT16, "ro", "tx", True, "6.1.3", 0),
    (0x605A, "Quick stop option code", INT16, "rw", "", False, "6.1.1", 0),
    (0x605B, "Shutdown option code", INT16, "rw", "", False, "Appendix 6", 0),
    (0x605C, "Disable operation option code", INT16, "rw", "", False, "Appendix 6", 0),
    (0x605E, "Fault reaction code", INT16, "rw", "", False, "Appendix 6", 0),
    (0x6060, "Modes of operation", INT8, "rw", "", True, "6.2", 8),
    (0x6061, "Modes of operation display", INT8, "ro", "", True, "6.2", 8),
    (0x6064, "Position actual value", INT32, "ro", "tx", True, "6.3.2", 0),
    (0x6065, "Following error window", UINT32, "rw", "", False, "Appendix 6", 0),
    (0x6066, "Following error time out", UINT16, "rw", "", False, "Appendix 6", 0),
    (0x606C, "Velocity actual value", INT32, "ro", "", False, "Appendix 6", 0),
    (0x6071, "Target torque", INT16, "ro", "", False, "Appendix 6", 0),
    (0x6077, "Torque actual value", INT16, "ro", "", False, "Appendix 6", 0),
    (0x607A, "Target position", INT32, "rw", "rx", True, "6.3.2", 0),
    (0x607C, "Home offset", UINT32, "rw", "", True, "6.4.1", 0),   # "U32": K48 signed in it
    (0x6085, "Quick stop deceleration", UINT32, "rw", "", False, "Appendix 6", 0),
    (0x6098, "Homing method", UINT8, "rw", "", True, "6.4.1", 1),
    (0x609A, "Homing acceleration", UINT32, "rw", "", True, "6.4.1", 0),
    (0x60B1, "Velocity offset", INT32, "rw", "", False, "Appendix 6", 0),
    (0x60B2, "Torque offset", INT16, "rw", "", False, "Appendix 6", 0),
    (0x60F4, "Following error actual value", INT32, "ro", "", False, "Appendix 6", 0),
    (0x60FD, "Digital inputs", UINT32, "ro", "", True, "6.5", 0),
    (0x60FF, "Target velocity", INT32, "rw", "", False, "Appendix 6", 0),
    (0x6502, "Supported drive modes", UINT32, "ro", "", True, "6.2", 0x000000A0),
    (0x67FE, "Homing switch input no", UINT32, "ro", "", False, "Appendix 6", 0),
)

#: 60F6h subindex 1h-4Fh = K21-K99: availability (CM1, CM2) per Appendix 6.
_K_AVAILABLE_CM1 = frozenset({23, 24, 26, 27, 33, 34, 42, 43, 45, 46, 47, 48, 52, 53, 54, 56,
                              57, 71, 72})
_K_AVAILABLE_CM2 = frozenset({23, 24, 26, 27, 33, 34, 42, 43, 45, 46, 47, 48, 56, 57, 64, 68})


def _axis(axis: int, firmware: str) -> list[Obj]:
    d = 0x800 * axis
    objs = [replace(var(idx + d, f"ID{axis + 1} {name}", dt, acc, default, pdo=pdo,
                        available=avail, section=sec), axis=axis + 1)
            for idx, name, dt, acc, pdo, avail, sec, default in _AXIS_VARS]
    k_ok = _K_AVAILABLE_CM1 if firmware == "cm1" else _K_AVAILABLE_CM2
    cm2 = firmware != "cm1"
    recs = [
        record(0x607B + d, f"ID{axis + 1} Position range limit", [
            Entry(1, "Min position range limit", INT32, "rw", available=False),
            Entry(2, "Max position range limit", INT32, "rw", available=False)],
            available=False),
        record(0x607D + d, f"ID{axis + 1} Software position limit", [
            Entry(1, "Min software position limit", INT32, "rw", available=False),
            Entry(2, "Max software position limit", INT32, "rw", available=False)],
            available=False, section="6.3"),
        record(0x6099 + d, f"ID{axis + 1} Homing speed", [
            Entry(1, "Speed during search for switch", UINT32, "rw"),
            Entry(2, "Speed during search for stopper", UINT32, "rw")], code=ARRAY,
            section="6.4.1"),
        record(0x60C2 + d, f"ID{axis + 1} Interpolation time period", [
            Entry(1, "Interpolation period", UINT8, "rw", available=False),
            Entry(2, "Interpolation index", INT8, "rw", available=False)], available=False),
        record(0x60E3 + d, f"ID{axis + 1} Supported homing method", [
            Entry(i + 1, name, INT16, default=i + 1) for i, name in enumerate(
                ("Stopper CW", "Stopper CCW", "Switch CW", "Switch CCW"))],
            code=ARRAY, section="6.4.1"),
        record(0x60F6 + d, f"ID{axis + 1} Cool Muscle K parameter", [
            Entry(k - 20, f"K{k} parameter", UINT32, "rw", available=k in k_ok)
            for k in range(21, 100)], code=ARRAY, section="Appendix 6",
            count_type=UINT32, count=0x4F),
        record(0x60FB + d, f"ID{axis + 1} Servo stiffness adjustment parameter", [
            Entry(1, "Servo stiffness adjustment", UINT32, "rw", available=cm2),
            *(Entry(s, "Reserved", UINT32, "rw", available=False) for s in range(2, 11))],
            code=ARRAY, available=cm2, count_type=UINT32, count=0x0A),
        record(0x60FE + d, f"ID{axis + 1} Digital outputs", [
            Entry(1, "Physical outputs", UINT32, "rw"),
            Entry(2, "Bit mask", UINT32, "rw")], code=ARRAY, section="6.5"),
    ]
    return objs + [replace(o, axis=axis + 1) for o in recs]


# -- manufacturer area (F000h-FFFFh) ---------------------------------------------
def _manufacturer(v: ident.Variant) -> list[Obj]:
    u32 = UINT32
    objs = [
        record(0xF000, "Modular device profile", [
            Entry(1, "Module index distance", UINT16, default=0x0800),
            Entry(2, "Maximum number of modules", UINT16, default=ident.AXES)]),
        record(0xF010, "Module profile list", [
            Entry(i + 1, f"ID{i + 1} device profile type", u32, default=0x00040192)
            for i in range(ident.AXES)], code=ARRAY),
        record(0xF030, "Configured module ident list", [
            Entry(i + 1, f"ID{i + 1} configured module ident", u32, default=0x00219800)
            for i in range(ident.AXES)], code=ARRAY),
        record(0xF050, "Module detected list", [
            Entry(i + 1, f"ID{i + 1} module detected", u32, default=0x00219800)
            for i in range(ident.AXES)], code=ARRAY),
    ]
    for i in range(ident.AXES):
        objs.append(record(0xF511 + i, f"Config axis{i + 1} (ID{i + 1} config info)", [
            Entry(1, "Type", u32, default=1 if v.firmware[i] == "cm1" else 2),
            Entry(2, "CommSpeed", u32, default=178_000),
            Entry(3, "CommTime", u32, default=1),
            Entry(4, "Reserved", u32, available=False)], section="2.2",
            count=4))                             # 7.3: "Number of Entries 4: Fixed"
    info = ([f"Axis{n} receive error (ID{n})" for n in range(1, 5)]
            + [f"Axis{n} motor error code (ID{n})" for n in range(1, 5)]
            + [f"Axis{n} serial send counter (ID{n})" for n in range(1, 5)]
            + [f"Axis{n} serial receive counter (ID{n})" for n in range(1, 5)]
            + ["PDO max time", "PDO min time", "PDO 1300 us time", "PDO 700 us time"]
            + [f"SystemInfo{n} (DEBUG)" for n in range(1, 5)])
    objs.append(record(0xF530, "SystemInfo",
                       [Entry(i + 1, name, u32) for i, name in enumerate(info)]))
    system = {1: "Musclecorp mode", 5: "Master mode", 6: "CM serial cycle (ms)",
              0x0B: "CoolMuscle device config code", 0x0C: "Serial number"}
    objs.append(record(0xF540, "Config system", [
        Entry(s, system.get(s, "Reserved"), u32, available=s in system,
              default=1 if s == 6 else (ident.SERIAL if s == 0x0C else 0))
        for s in range(1, 0x0D)]))
    tests = ("TestCommand-X", "TestCommand-Y", "TestCommand-Z", "TargetPositionFilter",
             "TestCommand1", "TestCommand2")
    objs.append(record(0xF550, "Test command (debug)",
                       [Entry(i + 1, name, u32) for i, name in enumerate(tests)]))
    objs += [var(0xF570, "SoftUpDateData", STRING, "rw", "", available=False),
             var(0xF571, "SoftUpDateInfo", STRING, "ro", "", available=False)]
    for i in range(ident.AXES):
        objs.append(replace(var(0xF581 + i, f"Axis{i + 1} CML command (ID{i + 1})", STRING,
                                "rw", "", section="7.2", max_len=64), axis=i + 1))
    for i in range(ident.AXES):
        objs.append(replace(var(0xF591 + i, f"Axis{i + 1} CML command response (ID{i + 1})",
                                STRING, "ro", "Null\r\n", section="7.2", max_len=64),
                            axis=i + 1))
    return objs




def build_table(code: str = ident.DEFAULT_VARIANT) -> Table:
    """The whole table for bridge ``code`` (EB01, EB02, EB12)."""
    v = ident.variant(code)
    objs = _communication(v)
    for axis in range(ident.AXES):
        objs += _axis(axis, v.firmware[axis])
    objs += _manufacturer(v)
    objs.sort(key=lambda o: o.index)
    return Table(tuple(objs))
