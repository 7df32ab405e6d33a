"""The EDS file of the CM1 EtherNet/IP module, written from :mod:`.objects` (ODVA EDS spec,
CIP Vol 1 ch. 7).

Identity, assembly sizes, the exclusive-owner connection and its RPI range are read
from the same definitions the adapter serves, so the file cannot disagree with the
device.  ``coolmuscle enip eds > CoolMuscle1.eds`` writes it; tests check it with
``eds-pie``.
"""

from __future__ import annotations

from ..cip.description import AssemblyInfo, ConnectionInfo
from .objects import ASSEMBLIES, DESCRIPTION, EXCLUSIVE_OWNER, IDENTITY

#: Trigger and transport (CIP Vol 1 7-3.6.11.1): class 1, cyclic, exclusive owner.
TRIGGER_EXCLUSIVE_OWNER = 0x04010002
#: Connection parameters (7-3.6.11.2): fixed sizes both ways; O->T 32-bit run/idle
#: header (format 4), T->O modeless; O->T point-to-point; T->O multicast or
#: point-to-point; scheduled priority.
PARAMS_HEADER = 0x44640405
PARAMS_MODELESS = 0x44640005

#: Members of each assembly (bits, name), manual 3.1 and 3.2.
MEMBERS = {
    0x65: ((16, "Communication error code"), (16, "Motor status code"),
           (32, "Motor position")),
    0x66: ((16, "Run/idle flag"), (32, "Position P0"), (32, "Speed S0"),
           (16, "Acceleration A0"), (8, "Control word"), (8, "IN2/OUT2 control (K52)")),
}

FILE_DATE = "12-01-2026"


def _q(text: str) -> str:
    return '"' + text.replace('"', "'") + '"'


def _file_section() -> list[str]:
    return ["[File]",
            f"        DescText = {_q(IDENTITY.product_name + ' (coolmuscle virtual module)')};",
            f"        CreateDate = {FILE_DATE};", "        CreateTime = 00:00:00;",
            f"        ModDate = {FILE_DATE};", "        ModTime = 00:00:00;",
            "        Revision = 1.0;", ""]


def _device_section() -> list[str]:
    ident = IDENTITY
    return ["[Device]",
            f"        VendCode = {ident.vendor_id};",
            f"        VendName = {_q(ident.vendor_name)};",
            f"        ProdType = {ident.device_type};",
            '        ProdTypeStr = "Generic Device (keyable)";',
            f"        ProdCode = {ident.product_code};", f"        MajRev = {ident.revision[0]};",
            f"        MinRev = {ident.revision[1]};",
            f"        ProdName = {_q(ident.product_name)};",
            '        Catalog = "CM1-EIP";', "",
            "[Device Classification]", "        Class1 = EtherNetIP;", ""]


def _params_section(conn: ConnectionInfo) -> list[str]:
    return ["[Params]",
            "        Param1 =", "                0,,,", "                0x0000,",
            "                0xC8,", "                4,",
            '                "RPI",', '                "Microsecond",',
            '                "Requested Packet Interval",',
            f"                {conn.rpi_min_us},{conn.rpi_max_us},{conn.rpi_default_us},",
            "                ,,,,", "                ,,,,", "                ;", ""]


def _assembly_entry(info: AssemblyInfo) -> list[str]:
    path = f"20 04 24 {info.instance:02X} 30 03"
    head = f"        Assem{info.instance} = {_q(info.name)}, {_q(path)}, {info.size}, 0x0000, , ,"
    members = MEMBERS.get(info.instance, ())
    if not members:
        return [head + " ;"]
    lines = [head]
    for i, (bits, name) in enumerate(members):
        end = ";" if i == len(members) - 1 else ","
        lines.append(f"                {bits}, {end}   $ {name}")
    return lines


def _assembly_section() -> list[str]:
    lines = ["[Assembly]", "        Revision = 2;"]
    for instance in sorted(ASSEMBLIES):
        lines += _assembly_entry(ASSEMBLIES[instance])
    return lines + [""]


def _connection_section(conn: ConnectionInfo) -> list[str]:
    out, inp, cfg = (ASSEMBLIES[conn.output], ASSEMBLIES[conn.input],
                     ASSEMBLIES[conn.config])
    path = f"20 04 24 {conn.config:02X} 2C {conn.output:02X} 2C {conn.input:02X}"
    params = PARAMS_HEADER if conn.run_idle_header else PARAMS_MODELESS
    return ["[Connection Manager]",
            "        Connection1 =",
            f"                0x{TRIGGER_EXCLUSIVE_OWNER:08X},"
            "   $ class 1, cyclic, exclusive owner",
            f"                0x{params:08X},   $ O->T run/idle header, T->O modeless",
            f"                Param1,{out.size},Assem{out.instance},   $ O->T RPI, size, format",
            f"                Param1,{inp.size},Assem{inp.instance},   $ T->O RPI, size, format",
            "                ,,   $ proxy config size, format",
            f"                {cfg.size},Assem{cfg.instance},   $ target config size, format",
            f"                {_q(conn.name)},", '                "",',
            f"                {_q(path)};", ""]


def _port_capacity_sections() -> list[str]:
    return ["[Port]",
            '        Port1 = TCP, "EtherNet/IP Port", "20 F5 24 01", 1;', "",
            "[Capacity]",
            f"        MaxIOConnections = {DESCRIPTION.max_io_connections};",
            f"        MaxMsgConnections = {DESCRIPTION.max_msg_connections};",
            "        TSpec1 = TxRx, 8, 500;", "        TSpec2 = TxRx, 14, 500;", ""]


def generate(conn: ConnectionInfo = EXCLUSIVE_OWNER) -> str:
    """The whole EDS text."""
    lines = ["$ EDS of the Cool Muscle 1 EtherNet/IP interface module",
             "$ written by coolmuscle from the objects the virtual module serves", ""]
    lines += _file_section() + _device_section() + _params_section(conn)
    lines += _assembly_section() + _connection_section(conn) + _port_capacity_sections()
    return "\n".join(lines) + "\n"
