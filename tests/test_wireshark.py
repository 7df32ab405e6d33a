"""Wireshark's dissectors as a second, independent oracle for every wire.

Each test captures with tshark a session that the usual peer drives (pysoem, pycomm3
and ethernetip, pymodbus, aiohttp), then reads the capture back with Wireshark's
ECAT/ECAT_MAILBOX (CoE), ENIP/CIP/CIP I/O, Modbus/TCP and WebSocket dissectors: no
frame may be malformed or carry an expert error, and the fields the dissector decodes
(object indices, SDO commands and toggles, CIP services and statuses, connection IDs,
sequence counts, Modbus function and exception codes, WebSocket opcodes) must equal
what the peer sent and got.  docs/wireshark.md shows the same captures by hand.

Captures need raw sockets: the tests are skipped, with the reason, where those are not
allowed (not root, no tshark); scripts/test installs Debian's tshark.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import os
import statistics
import struct
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.enip.cm1 import objects as enip_objects
from coolmuscle.frontends.ethercat.bridge import identity as ident
from coolmuscle.frontends.ethercat.lab import veth_pair
from coolmuscle.frontends.ethercat.transport import EthercatTransport
from coolmuscle.frontends.transports.modbus_tcp import ModbusTcpTransport
from coolmuscle.frontends.transports.service import ServiceThread
from ethercat_support import run_master
from fixtures import wait_until
from web_support import ask, serve, ws_frames
from wireshark_support import (
    Frame,
    capture_unavailable,
    capturing,
    dissect,
    in_net,
    ints,
    private_net,
    problems,
    sim_process,
    values,
)

WHY = capture_unavailable()
if WHY is not None and "tshark" in WHY and os.environ.get("CI"):
    raise RuntimeError(f"{WHY}: under CI the capture tests must run")
pytestmark = [pytest.mark.skipif(WHY is not None, reason=f"no capture: {WHY}"),
              pytest.mark.realtime]
PEERS = Path(__file__).parent / "capture_peers"
#: As in test_enip_peers: as root the module's T->O producer runs SCHED_FIFO, as a
#: deployment on a busy machine would (docs/enip.md).
RT = ("--enip-rt-priority", "10") if os.geteuid() == 0 else ()


#: What a peer session printed, the dissected frames, the capture file.
Session = tuple[dict[str, Any], list[Frame], Path]


def hexbytes(text: str) -> bytes:
    """A bytes field as tshark prints it (``aa:bb`` or ``aabb``)."""
    return bytes.fromhex(text.replace(":", ""))


# -- EtherCAT: SOEM through the bridge, INIT to OP, on a veth pair ----------------------
ECAT_FIELDS = ["frame.protocols", "ecat.cmd", "ecat.cnt", "ecat.data", "ecat.reg.alctrl.ctrl",
               "ecat.reg.alstatus.status", "ecat_mailbox.type", "ecat_mailbox.coe.type",
               "ecat_mailbox.coe.sdoreq", "ecat_mailbox.coe.sdores",
               "ecat_mailbox.coe.sdoidx", "ecat_mailbox.coe.sdosub",
               "ecat_mailbox.coe.sdodata", "ecat_mailbox.coe.sdolength",
               "ecat_mailbox.coe.dsoldata", "ecat_mailbox.coe.abortcode",
               "ecat_mailbox.coe.sdoccsid.complete", "ecat_mailbox.coe.sdoccsds.toggle",
               "ecat_mailbox.coe.sdoccsds.lastseg", "ecat_mailbox.coe.sdoscsus_toggle",
               "ecat_mailbox.coe.sdoscsus_lastseg", "ecat_mailbox.coe.sdoscsds_toggle",
               "ecat_mailbox.coe.sdoinfoopcode", "ecat_mailbox.coe.sdoinfofrag",
               "ecat_mailbox.coe.sdoinfolisttype", "ecat_mailbox.coe.sdoinfoindex",
               "ecat_mailbox.coe.sdoinfosubindex", "ecat_mailbox.coe.sdoinfoname",
               "ecat_mailbox.coe.sdoinfodatatype", "ecat_mailbox.coe.sdoinfobitlen"]
FPRD, FPWR, LRW = 0x04, 0x05, 0x0C
SDO_REQ, SDO_RES, SDO_INFO = 2, 3, 8


@pytest.fixture(scope="module")
def ecat(tmp_path_factory: pytest.TempPathFactory) -> Session:
    if os.geteuid() != 0:
        pytest.skip("veth pairs and network namespaces need root")
    path = tmp_path_factory.mktemp("ecat") / "ethercat.pcapng"
    with veth_pair(f"cmwse{os.getpid() % 1000}") as lab, capturing(lab.slave_if, path), \
            ServiceThread(lambda: Chain(None, 4, firmware="cm2"),
                          lambda: [EthercatTransport(lab.slave_if, "EB02")]):
        result = run_master(lab, "soem_master.py", "wire", timeout=110)
    return result, dissect(path, ECAT_FIELDS), path


def _mailboxes(frames: list[Frame], cmd: int) -> list[Frame]:
    """Mailbox datagrams the slave answered: FPWR (requests it took), FPRD (its answers)."""
    return [f for f in frames if "ecat_mailbox.type" in f and ints([f], "ecat.cmd")[0] == cmd
            and ints([f], "ecat.cnt")[0] == 1]


def _coe(frames: list[Frame], cmd: int, coe_type: int) -> list[Frame]:
    """The mailbox datagrams of one CoE service (SDO request, response, information)."""
    return [f for f in _mailboxes(frames, cmd)
            if ints([f], "ecat_mailbox.coe.type") == [coe_type]]


def test_ethercat_capture_has_no_malformed_frame_nor_expert_error(ecat: Session) -> None:
    _result, frames, path = ecat
    assert problems(path) == []
    assert {"ecatf", "ecat", "ecat_mailbox"} <= {p for f in frames
                                                for p in f["frame.protocols"][0].split(":")}


def test_ethercat_al_control_goes_init_preop_safeop_op_init_5_2(ecat: Session) -> None:
    result, frames, _path = ecat
    sent = [v for f in frames if ints([f], "ecat.cnt") == [0]
            for v in ints([f], "ecat.reg.alctrl.ctrl")]
    steps = [v for i, v in enumerate(sent) if i == 0 or sent[i - 1] != v]
    assert steps == [1, 2, 4, 8, 1], sent
    states = {v & 0x0F for v in ints(frames, "ecat.reg.alstatus.status")}
    assert {1, 2, 4, 8} <= states
    assert result["op"] == 8 and result["init"] == 1


def test_ethercat_sdo_requests_and_answers_are_the_ones_soem_made_5_4(ecat: Session) -> None:
    result, frames, _path = ecat
    requests = _coe(frames, FPWR, SDO_REQ)
    initiate = [(ints([f], "ecat_mailbox.coe.sdoreq")[0], ints([f], "ecat_mailbox.coe.sdoidx")[0],
                 ints([f], "ecat_mailbox.coe.sdosub")[0]) for f in requests
                if ints([f], "ecat_mailbox.coe.sdoreq")[0] in (1, 2)]
    index, sub = result["segmented"][:2]
    expected = ([(2, i, s) for i, s, _v in result["uploads"]]
                + [(1, i, s) for i, s, _v in result["downloads"]]
                + [(2, result["abort"][0], result["abort"][1]), (2, index, sub), (1, index, sub)])
    assert initiate[:len(expected)] == expected
    answers = _mailboxes(frames, FPRD)
    sdo = [f for f in answers if ints([f], "ecat_mailbox.coe.type") == [SDO_RES]]
    by_index: dict[tuple[int, int], Frame] = {}
    for f in sdo:
        if "ecat_mailbox.coe.sdoidx" in f and ints([f], "ecat_mailbox.coe.sdores") == [2]:
            key = (ints([f], "ecat_mailbox.coe.sdoidx")[0], ints([f], "ecat_mailbox.coe.sdosub")[0])
            by_index.setdefault(key, f)
    for i, s, value in result["uploads"]:
        answer = by_index[(i, s)]
        if "ecat_mailbox.coe.sdodata" in answer:          # expedited: the value itself
            assert ints([answer], "ecat_mailbox.coe.sdodata") == \
                [int.from_bytes(bytes.fromhex(value), "little")]
        else:                                             # normal: length and bytes
            assert ints([answer], "ecat_mailbox.coe.sdolength") == [len(value) // 2]
            assert hexbytes(answer["ecat_mailbox.coe.dsoldata"][0]) == bytes.fromhex(value)
    assert bytes.fromhex(result["uploads"][1][2]).decode() == ident.VARIANTS["EB02"].device_name
    downloaded = [(ints([f], "ecat_mailbox.coe.sdoidx")[0], ints([f], "ecat_mailbox.coe.sdosub")[0])
                  for f in sdo if ints([f], "ecat_mailbox.coe.sdores") == [3]]
    assert [(i, s) for i, s, _v in result["downloads"]] + [(index, sub)] == downloaded[:3]
    aborts = [f for f in answers if ints([f], "ecat_mailbox.coe.sdoreq") == [4]]
    assert ints(aborts, "ecat_mailbox.coe.abortcode") == [result["abort"][2]] == [0x06020000]


def test_ethercat_segmented_upload_and_download_carry_the_whole_object_5_4(ecat: Session) -> None:
    """60F6h complete access (the K parameters, 316 bytes) does not fit a 128-byte mailbox:
    SOEM uploads it in segments and downloads it back in segments (ETG.1000.6 5.6.2)."""
    result, frames, _path = ecat
    index, _sub, data_hex = result["segmented"]
    k = bytes.fromhex(data_hex)
    assert len(k) > ident.MBX_OUT_SIZE
    answers = _coe(frames, FPRD, SDO_RES)
    start = next(i for i, f in enumerate(answers)
                 if ints([f], "ecat_mailbox.coe.sdoidx") == [index]
                 and ints([f], "ecat_mailbox.coe.sdores") == [2])
    head, segments = answers[start], []
    for f in answers[start + 1:]:
        if ints([f], "ecat_mailbox.coe.sdores") != [0]:
            break
        segments.append(f)
    assert ints([head], "ecat_mailbox.coe.sdolength") == [len(k)]
    assert [ints([f], "ecat_mailbox.coe.sdoscsus_toggle")[0] for f in segments] == \
        [i % 2 for i in range(len(segments))]
    assert [ints([f], "ecat_mailbox.coe.sdoscsus_lastseg")[0] for f in segments][-1] == 1
    uploaded = b"".join(hexbytes(f["ecat_mailbox.coe.dsoldata"][0]) for f in [head, *segments])
    assert len(segments) >= 2 and uploaded[:len(k)] == k
    requests = _coe(frames, FPWR, SDO_REQ)
    start = next(i for i, f in enumerate(requests)
                 if ints([f], "ecat_mailbox.coe.sdoreq") == [1]
                 and ints([f], "ecat_mailbox.coe.sdoidx") == [index])
    head, pieces = requests[start], []
    for f in requests[start + 1:]:
        if ints([f], "ecat_mailbox.coe.sdoreq") != [0]:
            break
        pieces.append(f)
    assert ints([head], "ecat_mailbox.coe.sdoccsid.complete") == [1]
    assert ints([head], "ecat_mailbox.coe.sdolength") == [len(k)]
    assert [ints([f], "ecat_mailbox.coe.sdoccsds.toggle")[0] for f in pieces] == \
        [i % 2 for i in range(len(pieces))]
    downloaded = b"".join(hexbytes(f["ecat_mailbox.coe.dsoldata"][0]) for f in [head, *pieces])
    assert len(pieces) >= 2 and downloaded[:len(k)] == k
    confirms = [f for f in answers if ints([f], "ecat_mailbox.coe.sdores") == [1]]
    assert [ints([f], "ecat_mailbox.coe.sdoscsds_toggle")[0] for f in confirms] == \
        [i % 2 for i in range(len(pieces))]


def test_ethercat_sdo_information_names_what_soem_read_5_4(ecat: Session) -> None:
    result, frames, _path = ecat
    info_q = _coe(frames, FPWR, SDO_INFO)
    info_s = _coe(frames, FPRD, SDO_INFO)
    assert ints(info_q[:1], "ecat_mailbox.coe.sdoinfoopcode") == [1]          # Get OD List
    assert ints(info_q[:1], "ecat_mailbox.coe.sdoinfolisttype") == [1]        # all objects
    # The list spans mailboxes: every fragment but the last has the Incomplete bit (0x80),
    # which Wireshark 4.0 prints inside the opcode ("Unknown (130)"); fragments count down.
    lists = [f for f in info_s if ints([f], "ecat_mailbox.coe.sdoinfoopcode")[0] & 0x7F == 2]
    opcodes = [ints([f], "ecat_mailbox.coe.sdoinfoopcode")[0] for f in lists]
    left = [ints([f], "ecat_mailbox.coe.sdoinfofrag")[0] for f in lists]
    assert len(lists) >= 2 and opcodes == [0x82] * (len(lists) - 1) + [0x02]
    assert left == list(range(len(lists) - 1, -1, -1))
    assert len(result["od"]) > 50
    described = [(ints([f], "ecat_mailbox.coe.sdoinfoindex")[0],
                  f["ecat_mailbox.coe.sdoinfoname"][0])
                 for f in info_s if ints([f], "ecat_mailbox.coe.sdoinfoopcode") == [4]]
    assert [tuple(n) for n in result["names"]] == described
    entries = [(f["ecat_mailbox.coe.sdoinfoname"][0],
                ints([f], "ecat_mailbox.coe.sdoinfodatatype")[0],
                ints([f], "ecat_mailbox.coe.sdoinfobitlen")[0])
               for f in info_s if ints([f], "ecat_mailbox.coe.sdoinfoopcode") == [6]]
    assert [tuple(e) for e in result["entries"]] == entries
    assert entries[1] == ("Vendor ID", 0x0007, 32)


def test_ethercat_cyclic_csp_images_are_the_ones_exchanged_6_3_1(ecat: Session) -> None:
    """Every csp cycle's LRW datagram: the 24-byte output image SOEM sent and the 24-byte
    input image it read back, working counter 3 (outputs + inputs)."""
    result, frames, _path = ecat
    lrw = [f for f in frames if ints([f], "ecat.cmd") == [LRW] and ints([f], "ecat.cnt") != [0]]
    seen = [(f["ecat.data"][0].replace(":", "")[:48], f["ecat.data"][0].replace(":", "")[48:])
            for f in lrw]
    cycles = len(result["sent"])
    assert seen[-cycles:] == list(zip(result["sent"], result["seen"]))
    assert set(ints(lrw[-cycles:], "ecat.cnt")) == {3}
    status, position = struct.unpack_from("<Hi", bytes.fromhex(seen[-1][1]))
    target = struct.unpack_from("<Hi", bytes.fromhex(seen[-1][0]))[1]
    assert status & 0x6F == 0x27                       # operation enabled (6.1.1)
    assert target > 0 and abs(position - target) <= 100          # a few cycles behind


# -- EtherNet/IP: pycomm3 and ethernetip against the CM1 module on the standard ports ----
ENIP_FIELDS = ["frame.time_epoch", "frame.protocols", "enip.command", "enip.session",
               "enip.status", "enip.lir.name", "enip.lir.vendor", "enip.lir.prodcode",
               "cip.rr", "cip.sc", "cip.genstat", "cip.class", "cip.instance", "cip.attribute",
               "cip.id.product_name", "cip.cm.sc", "cip.cm.genstat", "cip.cm.ot_connid",
               "cip.cm.to_connid", "cip.cm.conn_serial_num", "cip.cm.otrpi", "cip.cm.torpi",
               "cip.cm.otapi", "cip.cm.toapi", "cip.cm.fwo.consize", "cip.cm.fwo.transport",
               "cip.connpoint", "enip.cpf.sai.connid", "enip.cpf.sai.seq", "cip.seq",
               "cip.32bitheader.run_idle", "cipio.data"]


@pytest.fixture(scope="module")
def enip(tmp_path_factory: pytest.TempPathFactory) -> Session:
    if os.geteuid() != 0:
        pytest.skip("a network namespace of its own needs root")
    path = tmp_path_factory.mktemp("enip") / "enip.pcapng"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    with private_net() as ns, \
            sim_process(ns, "--firmware", "cm1", "--enip", *RT,
                        banner=r"enip: 127\.0\.0\.1:44818 \(I/O udp 2222\)"), \
            capturing("lo", path, namespace=ns):
        done = subprocess.run(in_net(ns, [sys.executable, str(PEERS / "enip_session.py")]),
                              capture_output=True, text=True, timeout=90, env=env, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1]), dissect(path, ENIP_FIELDS), path


def test_enip_capture_has_no_malformed_frame_nor_expert_error(enip: Session) -> None:
    _result, frames, path = enip
    assert problems(path) == []
    found = {p for f in frames for p in f["frame.protocols"][0].split(":")}
    assert {"enip", "cip", "cipcm", "cipio"} <= found


def test_enip_list_identity_and_register_session_cip_vol2_2_4(enip: Session) -> None:
    result, frames, _path = enip
    identities = [f for f in frames if "enip.lir.name" in f]
    assert values(identities, "enip.lir.name") == [enip_objects.IDENTITY.product_name] * 2
    assert set(ints(identities, "enip.lir.vendor")) == {enip_objects.IDENTITY.vendor_id}
    assert set(ints(identities, "enip.lir.prodcode")) == {enip_objects.IDENTITY.product_code}
    assert result["udp_identity"] == result["tcp_identity"] == enip_objects.IDENTITY.product_name
    registered = {ints([f], "enip.session")[0] for f in frames
                  if ints([f], "enip.command") == [0x65] and ints([f], "enip.session") != [0]}
    used = {ints([f], "enip.session")[0] for f in frames if ints([f], "enip.command") == [0x6F]}
    assert len(registered) == 4 and used <= registered


def test_enip_get_set_attribute_services_and_statuses_cip_vol1_appendix_b(enip: Session) -> None:
    result, frames, _path = enip
    answers = [f for f in frames if "cip.sc" in f and "cip.cm.sc" not in f
               and ints([f], "cip.rr") == [1]]
    got: list[list[int | None]] = [
        [ints([f], "cip.sc")[0], ints([f], "cip.class")[0], ints([f], "cip.instance")[0],
         ints([f], "cip.attribute")[0] if "cip.attribute" in f else None,
         ints([f], "cip.genstat")[0]] for f in answers]
    assert got[:-1] == result["requests"]
    assert got[-1] == [0x0E, 4, 0x65, 3, 0]                 # the input assembly, afterwards
    assert [r[4] for r in result["requests"][3:]] == result["expected"] == [0x05, 0x14, 0x0E, 0x08]
    assert values(answers, "cip.id.product_name") == [result["name"]]


def test_enip_forward_open_class1_io_both_ways_and_forward_close_ch4(enip: Session) -> None:
    result, frames, _path = enip
    assert result["forward_open"] == 0 and result["forward_close"] == 0
    cm = [f for f in frames if "cip.cm.sc" in f]
    request, reply = cm[0], cm[1]
    assert ints([request], "cip.cm.sc") == [0x54] and ints([reply], "cip.genstat") == [0]
    assert ints([request], "cip.cm.otrpi") == ints([request], "cip.cm.torpi") == [10_000]
    assert ints([request], "cip.cm.fwo.consize") == [20, 10]       # 14 + 2 + 4, 8 + 2
    assert ints([request], "cip.connpoint") == [0x66, 0x65]
    assert ints([reply], "cip.cm.ot_connid") == [result["ot_id"]]
    assert ints([reply], "cip.cm.to_connid") == [result["to_id"]]
    assert ints([reply], "cip.cm.otapi") == ints([reply], "cip.cm.toapi") == [10_000]
    close = [f for f in cm if ints([f], "cip.cm.sc") == [0x4E]]
    assert len(close) == 2 and ints(close[1:], "cip.genstat") == [0]
    assert ints(close, "cip.cm.conn_serial_num") == ints([request], "cip.cm.conn_serial_num") * 2
    io = [f for f in frames if "cipio" in f["frame.protocols"][0]]
    o_t = [f for f in io if ints([f], "enip.cpf.sai.connid") == [result["ot_id"]]]
    t_o = [f for f in io if ints([f], "enip.cpf.sai.connid") == [result["to_id"]]]
    assert len(o_t) > 10 and len(t_o) > 30 and len(o_t) + len(t_o) == len(io)
    for stream in (o_t, t_o):
        seq = ints(stream, "enip.cpf.sai.seq")
        assert seq == list(range(seq[0], seq[0] + len(seq)))           # +1 a packet
        counts = ints(stream, "cip.seq")
        assert all(0 <= b - a <= 1 for a, b in itertools.pairwise(counts))
        assert counts[-1] > counts[0]
    assert set(ints(o_t, "cip.32bitheader.run_idle")) == {1}            # run
    assert {hexbytes(v) for v in values(o_t, "cipio.data")} == {bytes.fromhex(result["move"])}
    images = [struct.unpack("<HHi", hexbytes(v)) for v in values(t_o, "cipio.data")]
    assert images[-1] == (0, 8, 4000) == tuple(result["input"]) == tuple(result["after"])
    assert any(status == 0 for _e, status, _p in images)                # running first
    times = [float(v) for v in values(t_o, "frame.time_epoch")]
    median = statistics.median(b - a for a, b in itertools.pairwise(times))
    assert abs(median - 0.010) < 0.002, median                          # RPI 10 ms


# -- Modbus/TCP: pymodbus, every function code the slave serves and its exceptions -------
MODBUS_FIELDS = ["frame.protocols", "tcp.srcport", "tcp.dstport", "mbtcp.trans_id",
                 "mbtcp.unit_id", "modbus.func_code",
                 "modbus.exception_code", "modbus.request_frame", "modbus.regnum16",
                 "modbus.regval_uint16", "modbus.reference_num", "modbus.word_cnt"]
MOVE = b"S.1=100, A.1=100, P.1=2000, ^.1\r"


def _words(text: bytes) -> list[int]:
    text += b"\x00" * (len(text) % 2)
    return [int.from_bytes(text[i:i + 2], "big") for i in range(0, len(text), 2)]


def test_modbus_tcp_function_codes_and_exceptions_dissect_as_sent_5_6_7(tmp_path: Path) -> None:
    from pymodbus.client import ModbusTcpClient
    st = ServiceThread(lambda: Chain(motors=1), lambda: [ModbusTcpTransport(port=0)]).start()
    port = st.transports[0].info()["port"]
    path = tmp_path / "modbus.pcapng"
    try:
        with capturing("lo", path, f"tcp port {port}"):
            client: Any = ModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
            assert client.connect()
            try:
                calls = [  # (function code, exception code or None) as pymodbus saw them
                    (client.write_registers(200, [0, 12345], device_id=1), 16),
                    (client.read_holding_registers(200, count=2, device_id=1), 3),
                    (client.read_input_registers(32, count=1, device_id=1), 4),
                    (client.write_registers(102, _words(MOVE), device_id=1), 16),
                    (client.read_holding_registers(42, count=2, device_id=1), 3),
                    (client.read_input_registers(100, count=2, device_id=1), 4),
                    (client.write_registers(0, [0, 1], device_id=1), 16),
                    (client.read_coils(0, count=8, device_id=1), 1),
                    (client.write_register(200, 7, device_id=1), 6),
                ]
                assert wait_until(lambda: st.call(lambda: st.chain.snapshot(1).position) == 2000)
            finally:
                client.close()
    finally:
        st.stop()
    sent: list[tuple[int, int | None]] = [
        (fc, int(r.exception_code) if r.isError() else None) for r, fc in calls]
    assert sent == [(16, None), (3, None), (4, None), (16, None), (3, 2), (4, 2), (16, 2),
                    (1, 1), (6, 1)]
    assert problems(path, ["-o", f"mbtcp.tcp.port:{port}"]) == []
    frames = dissect(path, MODBUS_FIELDS, "mbtcp", ["-o", f"mbtcp.tcp.port:{port}"])
    queries = [f for f in frames if ints([f], "tcp.dstport") == [port]]
    answers = [f for f in frames if ints([f], "tcp.srcport") == [port]]
    assert ints(queries, "mbtcp.trans_id") == ints(answers, "mbtcp.trans_id") == \
        list(range(1, len(sent) + 1))
    assert set(ints(frames, "mbtcp.unit_id")) == {1}
    assert [(ints([f], "modbus.func_code")[0], next(iter(ints([f], "modbus.exception_code")), None))
            for f in answers] == sent
    assert ints(queries, "modbus.func_code") == [fc for fc, _e in sent]
    assert ints(queries[:1], "modbus.regval_uint16") == [0, 12345]
    assert ints(answers[1:2], "modbus.regnum16") == [200, 201]
    assert ints(answers[1:2], "modbus.regval_uint16") == [0, 12345]
    assert ints(answers[2:3], "modbus.regval_uint16") == [8]               # Ux: in position
    assert ints(queries[3:4], "modbus.regval_uint16") == _words(MOVE)      # the CML command


# -- WebSocket: the dashboard's socket, as aiohttp (test_web_server's client) uses it ----
WS_FIELDS = ["frame.protocols", "tcp.srcport", "http.response.code", "http.upgrade",
             "websocket.opcode", "websocket.mask", "websocket.payload.text",
             "websocket.payload.close.status_code"]


def test_web_dashboard_websocket_session_dissects_as_sent(tmp_path: Path) -> None:
    import aiohttp
    st = serve(motors=1)
    port = st.transports[1].info()["port"]
    path = tmp_path / "web.pcapng"
    request = {"t": "cml", "line": "?96.1"}
    got: dict[str, Any] = {}

    async def session() -> None:
        async with aiohttp.ClientSession() as http, \
                http.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:
            got["hello"] = await ws_frames(ws, lambda f: f["t"] == "hello")
            got["result"] = await ask(ws, request)
            await ws.send_bytes(b"\x01\x02")
            got["binary"] = await ws_frames(ws, lambda f: f.get("t") == "result"
                                            and "error" in f)
            await ws.ping(b"cm")
    try:
        with capturing("lo", path, f"tcp port {port}"):
            asyncio.run(session())
    finally:
        st.stop()
    assert got["result"]["replies"] == ["Px.1=0"]
    decode = ["-d", f"tcp.port=={port},http"]
    assert problems(path, decode) == []
    frames = dissect(path, WS_FIELDS, "http or websocket", decode)
    upgrade = [f for f in frames if ints([f], "http.response.code") == [101]]
    assert values(upgrade, "http.upgrade") == ["websocket"]
    ws = [f for f in frames if "websocket.opcode" in f]
    to_server = [f for f in ws if ints([f], "tcp.srcport") != [port]]
    to_client = [f for f in ws if ints([f], "tcp.srcport") == [port]]
    assert ints(to_server, "websocket.opcode") == [1, 2, 9, 8]    # text, binary, ping, close
    assert values(to_server, "websocket.mask") == ["1"] * 4 or \
        values(to_server, "websocket.mask") == ["True"] * 4                # RFC 6455 5.3
    assert set(values(to_client, "websocket.mask")) <= {"0", "False"}
    assert json.loads(values(to_server, "websocket.payload.text")[0]) == {**request, "id": 1}
    texts = [json.loads(line) for f in to_client if ints([f], "websocket.opcode") == [1]
             for line in values([f], "websocket.payload.text")[0].split("\n")]
    assert texts[0]["t"] == "hello" and got["hello"] == texts[0]
    assert got["result"] in texts and got["binary"] in texts
    assert {10, 8} <= set(ints(to_client, "websocket.opcode"))            # pong, close
    assert set(ints(ws, "websocket.payload.close.status_code")) == {1000}
