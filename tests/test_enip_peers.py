"""The CM1 EtherNet/IP adapter against independent peers: pycomm3, cpppo, ethernetip, eds-pie.

cm1-ethernetip-interface-manual.txt 3.1-3.3 and ch. 4; CIP general status codes
(CIP Vol 1 appendix B).  Everything runs on 127.0.0.1 with free ports.
"""

from __future__ import annotations

import logging
import math
import os
import socket
import struct
import time

import pytest

from coolmuscle.frontends.enip.cm1 import objects
from coolmuscle.frontends.enip.cm1.eds import generate
from enip_support import KernelStamps, enip_process, enip_service, ports
from fixtures import wait_until

pycomm3 = pytest.importorskip("pycomm3")
from pycomm3 import CIPDriver  # noqa: E402

pytestmark = [pytest.mark.peer, pytest.mark.realtime]

EXAMPLE_VALUES = struct.pack("<HiihBB", 1, 100000, 100, 10, 1, 0)   # 3.2, its stated values


@pytest.fixture(scope="module")
def service():
    with enip_service(scale=20.0) as st:     # 20 virtual seconds a wall second: moves end soon
        yield st


def driver(st) -> CIPDriver:
    return CIPDriver(f"127.0.0.1:{ports(st)[0]}")


def get(d: CIPDriver, cls: int, inst: int, attr: int, connected: bool = False):
    return d.generic_message(service=0x0E, class_code=cls, instance=inst, attribute=attr,
                             connected=connected, route_path=False)


def set_(d: CIPDriver, cls: int, inst: int, attr: int, data: bytes):
    return d.generic_message(service=0x10, class_code=cls, instance=inst, attribute=attr,
                             request_data=data, connected=False, route_path=False)


def generic_status(d: CIPDriver, **kw) -> int:
    response = d.generic_message(connected=False, route_path=False,
                                 return_response_packet=True, **kw)
    return response.value.service_status


def test_pycomm3_list_identity():
    with enip_service() as st:
        ident = CIPDriver.list_identity(f"127.0.0.1:{ports(st)[0]}")
    assert ident["product_name"] == objects.IDENTITY.product_name
    assert ident["product_code"] == objects.IDENTITY.product_code
    assert ident["revision"] == {"major": 1, "minor": 7}
    assert ident["ip_address"] == "127.0.0.1" and ident["state"] == 3


def test_3_1_pycomm3_get_input_assembly_returns_8_bytes(service):
    with driver(service) as d:
        tag = get(d, 4, 0x65, 3)
    assert tag.error is None and len(tag.value) == 8
    code, status, _position = struct.unpack("<HHi", tag.value)
    assert code == 0 and status in (0, 8)


def test_3_2_pycomm3_set_output_example_moves_motor_to_100000(service):
    with driver(service) as d:
        assert set_(d, 4, 0x66, 3, struct.pack("<HiihBB", 1, 0, 100, 10, 0, 0)).error is None
        assert set_(d, 4, 0x66, 3, EXAMPLE_VALUES).error is None
        assert get(d, 4, 0x66, 3).value == EXAMPLE_VALUES
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            code, status, position = struct.unpack("<HHi", get(d, 4, 0x65, 3).value)
            if status == 8 and position == 100000:
                break
            time.sleep(0.05)
        assert (code, status, position) == (0, 8, 100000)
        assert service.call(service.chain.snapshot, 1).position == 100000


def test_3_2_example_bytes_verbatim_command_1000000(service):
    """The data line of 3.2 is little endian: its P0 bytes 40 42 0F 00 are 1,000,000."""
    example = bytes.fromhex("01 00 40 42 0F 00 64 00 00 00 0A 00 01 00")
    with driver(service) as d:
        set_(d, 4, 0x66, 3, struct.pack("<HiihBB", 1, 0, 100, 10, 0, 0))
        assert set_(d, 4, 0x66, 3, example).error is None
        time.sleep(0.1)
        assert service.call(service.chain.register_value, 1, "P", 0) == 1_000_000
        assert struct.unpack("<HHi", get(d, 4, 0x65, 3).value)[1] == 0   # running
        set_(d, 4, 0x66, 3, struct.pack("<HiihBB", 1, 0, 100, 100, 2, 0))  # stop


@pytest.mark.parametrize("request_kw, status", [
    (dict(service=0x0E, class_code=4, instance=0x67, attribute=3), 0x05),   # absent instance
    (dict(service=0x0E, class_code=0x99, instance=1, attribute=1), 0x05),   # absent class
    (dict(service=0x0E, class_code=4, instance=0x65, attribute=9), 0x14),   # no attribute
    (dict(service=0x10, class_code=4, instance=0x65, attribute=3,
          request_data=bytes(8)), 0x0E),                                    # input read-only
    (dict(service=0x10, class_code=4, instance=0x66, attribute=3,
          request_data=bytes(13)), 0x13),                                   # not enough data
    (dict(service=0x10, class_code=4, instance=0x66, attribute=3,
          request_data=bytes(15)), 0x15),                                   # too much data
    (dict(service=0x4B, class_code=1, instance=1), 0x08),                   # no such service
    (dict(service=0x01, class_code=4, instance=0x65), 0x08),                # no Get_All there
], ids=["instance", "class", "attribute", "read-only", "short", "long", "service", "get-all"])
def test_cip_general_status_of_each_refusal(service, request_kw, status):
    with driver(service) as d:
        assert generic_status(d, **request_kw) == status


def test_3_1_1_vendor_class_0x64_reads_comm_error_code(service):
    with driver(service) as d:
        tag = get(d, 0x64, 1, 0x64)
    assert tag.error is None and tag.value == b"\x00\x00"


def test_pycomm3_class3_connected_messaging(service):
    """pycomm3's connected=True opens a class 3 connection (Large_Forward_Open) first."""
    with driver(service) as d:
        tag = get(d, 4, 0x65, 3, connected=True)
        ident = d.generic_message(service=0x01, class_code=1, instance=1, connected=True)
    assert tag.error is None and len(tag.value) == 8
    assert ident.error is None and objects.IDENTITY.product_name.encode() in ident.value


def test_tcpip_and_ethernet_link_objects(service):
    with driver(service) as d:
        status = get(d, 0xF5, 1, 1)
        config = get(d, 0xF5, 1, 5)
        mac = get(d, 0xF6, 1, 3)
    assert status.value == struct.pack("<I", 1)
    assert struct.unpack_from("<I", config.value)[0] == 0x7F000001
    assert len(mac.value) == 6


def test_cpppo_client_reads_the_same_attributes(service):
    from cpppo.server.enip.get_attribute import proxy_simple
    via = proxy_simple(host="127.0.0.1", port=ports(service)[0])
    with via:
        input_sint, comm, name, absent = via.read(
            [("@4/101/3", "SINT"), ("@0x64/1/0x64", "UINT"), ("@1/1/7", "SSTRING"),
             ("@4/103/3", "SINT")])
        ident = via.list_identity()
    with driver(service) as d:
        ours = get(d, 4, 0x65, 3).value
    assert len(input_sint) == 8 and bytes(v & 0xFF for v in input_sint)[:4] == ours[:4]
    assert comm == [0] and name == [objects.IDENTITY.product_name] and absent is None
    assert ident.product_name == objects.IDENTITY.product_name
    assert ident.vendor_id == objects.IDENTITY.vendor_id


def _import_eds_pie():
    """eds-pie calls ``logging.basicConfig(level=DEBUG)`` when imported: undo that for the
    rest of the suite."""
    root = logging.getLogger()
    level, handlers = root.level, list(root.handlers)
    from eds_pie.eds_pie import CIP_EDS
    root.setLevel(level)
    root.handlers[:] = handlers
    return CIP_EDS


def test_eds_pie_parses_the_generated_eds(caplog, service):
    CIP_EDS = _import_eds_pie()
    with caplog.at_level(logging.WARNING):
        eds = CIP_EDS(generate())
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    # eds-pie 1.2.0 has no definitions for [Port] entries (only warnings, about them)
    foreign = [r for r in caplog.records if r.levelno == logging.WARNING
               and "Port" not in r.getMessage() and "Unknown Entry" not in r.getMessage()]
    assert not errors and not foreign, [r.getMessage() for r in caplog.records]
    assert eds.protocol == "EtherNetIP"
    assert eds.get_value("Device", "VendCode") == objects.IDENTITY.vendor_id
    assert eds.get_value("Device", "ProdCode") == objects.IDENTITY.product_code
    with driver(service) as d:
        for inst in (0x65, 0x66, 0x80):
            size = struct.unpack("<H", get(d, 4, inst, 4).value)[0]
            assert eds.get_value("Assembly", f"Assem{inst}", 2) == size
    assert eds.get_value("Connection Manager", "Connection1", 3) == 14     # ch. 4: 102/14
    assert eds.get_value("Connection Manager", "Connection1", 6) == 8      # ch. 4: 101/8
    assert str(eds.get_field("Connection Manager", "Connection1", 14)) == "20 04 24 80 2C 66 2C 65"


# -- Class 1: the ethernetip package as originator, against `coolmuscle sim` ---------------
class _Scanner:
    """The ``ethernetip`` PyPI package's EtherNetIP / EtherNetIPExpConnection, pointed at our
    ports."""

    def __init__(self, monkeypatch, tcp_port: int, io_port: int) -> None:
        import ethernetip.ethernetip as E
        monkeypatch.setattr(E, "ENIP_TCP_PORT", tcp_port)
        monkeypatch.setattr(E, "ENIP_UDP_PORT", io_port)
        self.enip = E.EtherNetIP("127.0.0.1")
        self.conn = self.enip.explicit_conn("127.0.0.1")
        self.inp = self.enip.registerAssembly(E.EtherNetIP.ENIP_IO_TYPE_INPUT, 8, 101, self.conn)
        self.out = self.enip.registerAssembly(E.EtherNetIP.ENIP_IO_TYPE_OUTPUT, 14, 102, self.conn)
        self.enip.startIO(udp_port=0)
        self.stamps = KernelStamps(self.enip.udpsock)
        self.enip.udpsock = self.stamps
        self.times = self.stamps.times
        assert self.conn.registerSession() == 0

    def forward_open(self, rpi_ms: int = 10, multiplier: int = 2):
        return self.conn.sendFwdOpenReq(101, 102, 128, torpi=rpi_ms, otrpi=rpi_ms,
                                        multiplier=multiplier,
                                        originator_udp_port=self.enip.originator_udp_port)

    def set_output(self, data: bytes) -> None:
        for i, byte in enumerate(data):
            for bit in range(8):
                self.out[i * 8 + bit] = bool(byte >> bit & 1)

    def input(self) -> tuple[int, int, int]:
        raw = bytes(sum(1 << b for b in range(8) if self.inp[i * 8 + b]) for i in range(8))
        return struct.unpack("<HHi", raw)

    def close(self) -> None:
        self.conn.stopProduce()
        self.enip.stopIO()


def _owned(tcp_port: int) -> bool:
    with CIPDriver(f"127.0.0.1:{tcp_port}") as d:
        status = struct.unpack("<H", get(d, 1, 1, 5).value)[0]
    return bool(status & 0x0001)


def _grid_lateness(times: list[float], rpi: float) -> list[float]:
    """How late each packet came after its slot on the producer's RPI grid (CIP Vol 1
    3-4.4: productions are due every RPI, in phase; io.py ``due`` keeps that phase after a
    late one and skips, rather than bursts, a slot more than an RPI late).  The grid's
    phase is the circular mean of the packets' phases (most productions are on time);
    a packet up to 3/4 RPI after its slot counts as late, so one late production counts
    once, not twice as it would in the intervals (a long one and a short one).  A
    producer that loses its phase spreads the phases and fails."""
    turns = [2 * math.pi * ((t - times[0]) % rpi) / rpi for t in times]
    phase = math.atan2(sum(map(math.sin, turns)), sum(map(math.cos, turns))) * rpi / (2 * math.pi)
    return [(t - times[0] - phase + rpi / 4) % rpi - rpi / 4 for t in times]


#: The suite shares two cores with other work: as root the adapter's producer thread runs
#: SCHED_FIFO (``--enip-rt-priority``), as a deployment on a busy machine would.
RT = ("--enip-rt-priority", "10") if hasattr(os, "geteuid") and os.geteuid() == 0 else ()


def test_ch4_ethernetip_class1_io_moves_motor_and_times_out(monkeypatch):
    """Forward_Open 101/102/128 at RPI 10 ms; T->O intervals; a move through O->T;
    the originator falls silent: the connection times out; Forward_Close stops production.
    (A 3 s run instead of the 60 s of the acceptance; bench/bench_enip.py runs that.)"""
    with enip_process(*RT) as (_proc, tcp_port, io_port):
        scanner = _Scanner(monkeypatch, tcp_port, io_port)
        try:
            assert scanner.forward_open() == 0
            assert (scanner.conn.otapi, scanner.conn.toapi) == (10, 10)
            scanner.set_output(struct.pack("<HiihBB", 1, 4000, 100, 100, 1, 0))
            scanner.conn.produce()
            assert wait_until(lambda: scanner.input() == (0, 8, 4000), 5), scanner.input()
            assert _owned(tcp_port)
            time.sleep(max(0.0, 3.0 - (scanner.times[-1] - scanner.times[0])))
            late = _grid_lateness(scanner.times, 0.010)
            good = sum(abs(off) <= 0.002 for off in late)
            assert len(late) > 250 and good >= 0.95 * len(late), \
                (good, len(late), max(late))
            scanner.conn.stopProduce()                  # silent originator
            assert wait_until(lambda: not _owned(tcp_port), 2)   # 16 x 10 ms timeout
            count = len(scanner.times)
            time.sleep(0.2)
            assert len(scanner.times) == count           # production stopped
            assert scanner.forward_open() == 0           # a new connection, then closed
            scanner.conn.produce()
            assert wait_until(lambda: len(scanner.times) > count + 5, 2)
            scanner.conn.stopProduce()
            assert scanner.conn.sendFwdCloseReq(101, 102, 128) == 0
            count = len(scanner.times)
            time.sleep(0.2)
            assert len(scanner.times) <= count + 1 and not _owned(tcp_port)
        finally:
            scanner.close()


def test_pycomm3_unconnected_send_is_unwrapped(service):
    """pycomm3 with ``unconnected_send=True`` wraps the request in Unconnected_Send (0x52)."""
    with driver(service) as d:
        tag = d.generic_message(service=0x0E, class_code=4, instance=0x65, attribute=3,
                                connected=False, unconnected_send=True, route_path=True)
    assert tag.error is None and len(tag.value) == 8


def test_multicast_t_o_reaches_a_joined_member():
    """A hand-written originator (ours, not a peer): Forward_Open with T->O multicast; the
    reply's T->O sockaddr item names the group (CIP Vol 2 3-5.3); packets arrive there."""
    from coolmuscle.frontends.enip.cip import encapsulation as enc
    from test_enip_encapsulation import decode, forward_open, frame, o_t, rr_data
    with enip_service() as st:
        tcp_port, io_port = ports(st)
        with socket.create_connection(("127.0.0.1", tcp_port), timeout=3) as tcp:
            tcp.sendall(frame(enc.REGISTER_SESSION, struct.pack("<HH", 1, 0)).encode())
            handle = decode(tcp.recv(1024)).session
            request = forward_open(rpi=10_000, to_type=1, multiplier=7)    # x512: 5 s
            tcp.sendall(frame(enc.SEND_RR_DATA, rr_data(request), handle).encode())
            items = enc.parse_cpf(decode(tcp.recv(1024)).data[6:])
            reply = items[1].data
            assert reply[2] == 0, reply.hex()
            ot_id = struct.unpack_from("<I", reply, 4)[0]
            to_item = next(i for i in items if i.type_id == enc.ITEM_SOCKADDR_TO)
            port, group = enc.parse_sockaddr(to_item.data)
            group_ip = socket.inet_ntoa(struct.pack(">I", group))
            assert (group_ip, port) == ("239.192.1.0", io_port)
            member = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            member.bind((group_ip, port))
            member.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                              socket.inet_aton(group_ip) + socket.inet_aton("127.0.0.1"))
            member.settimeout(2)
            out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            out.sendto(o_t(ot_id, 1, 1, struct.pack("<HiihBB", 1, 0, 100, 100, 0, 0)),
                       ("127.0.0.1", io_port))
            got = [member.recv(100) for _ in range(5)]
            member.close()
            out.close()
        for packet in got:
            address, data = enc.parse_cpf(packet)
            assert address.type_id == enc.ITEM_SEQUENCED_ADDRESS and len(data.data) == 10
        assert struct.unpack_from("<HH", got[-1], 20)[1] == 8      # motor status: in position


def test_ethernetip_list_identity_over_udp(monkeypatch):
    """ListIdentity over UDP 44818 (CIP Vol 2 2-4.2), as the ethernetip package sends it."""
    import ethernetip.ethernetip as E
    with enip_service() as st:
        monkeypatch.setattr(E, "ENIP_TCP_PORT", ports(st)[0])
        reply = E.EtherNetIP("127.0.0.1").listIDUDP("127.0.0.1", timeout=3)
    assert reply is not None
    assert reply.product_name == objects.IDENTITY.product_name.encode()
    assert (reply.vendor_id, reply.product_code) == (objects.IDENTITY.vendor_id,
                                                     objects.IDENTITY.product_code)


def test_pycomm3_default_route_path_set_is_accepted(service):
    """pycomm3's defaults append its empty route path (00 00) after the data; an exact
    14-byte image followed by exactly that is accepted, other extra bytes are not."""
    idle = struct.pack("<HiihBB", 0, 0, 100, 10, 0, 0)
    with driver(service) as d:
        tag = d.generic_message(service=0x10, class_code=4, instance=0x66, attribute=3,
                                request_data=idle, connected=False)
        assert tag.error is None
        assert get(d, 4, 0x66, 3).value == idle
        assert generic_status(d, service=0x10, class_code=4, instance=0x66, attribute=3,
                              request_data=idle + b"\x01\x00") == 0x15


def test_ch4_rpi_2ms_accepted_and_produced_on_time(monkeypatch):
    """RPI 2 ms, the smallest the module takes: the T->O packets come every 2 ms, at
    least 90 % of the slots filled, each packet judged against its slot on the RPI grid
    (median within 0.1 ms, 90 % within ± 0.5 ms over 1.5 s; see ``_grid_lateness``).
    ethernetip itself produces O->T every 8 ms at the fastest, so the multiplier is 4
    (x64 = 128 ms)."""
    with enip_process(*RT) as (_proc, tcp_port, io_port):
        scanner = _Scanner(monkeypatch, tcp_port, io_port)
        try:
            assert scanner.forward_open(rpi_ms=2, multiplier=4) == 0
            assert scanner.conn.toapi == 8         # ethernetip clamps what it reports ...
            scanner.set_output(struct.pack("<HiihBB", 1, 0, 100, 100, 0, 0))
            scanner.conn.produce()
            time.sleep(1.5)
            times = scanner.times[:]
            span = times[-1] - times[0]
            assert len(times) > 600 and len(times) >= 0.9 * span / 0.002   # ... but 2 ms
            late = sorted(_grid_lateness(times, 0.002))
            assert abs(late[len(late) // 2]) < 0.0001, late[len(late) // 2]
            good = sum(abs(off) <= 0.0005 for off in late)
            assert good >= 0.9 * len(late), (good, len(late), late[-5:])
            scanner.conn.stopProduce()
            assert scanner.conn.sendFwdCloseReq(101, 102, 128) == 0
        finally:
            scanner.close()


def test_class1_model_work_runs_outside_the_producer_lock(monkeypatch):
    """The model's thread writes an O->T image to the motor and reads the input image
    without the connection table's lock, so the T->O producer thread (CIP Vol 1 3-4.4)
    never waits for the model; the switch interval is cut while the producer runs and
    set back when it stops."""
    import sys

    from coolmuscle.frontends.enip.cip import encapsulation as enc
    from coolmuscle.frontends.enip.cip.producer import SWITCH_INTERVAL
    from coolmuscle.frontends.enip.cm1.adapter import Cm1Module
    from test_enip_encapsulation import decode, forward_open, frame, o_t, rr_data
    held: dict[str, list[bool]] = {"write_output": [], "input_image": []}
    box: list = []
    for name in held:
        original = getattr(Cm1Module, name)

        def spy(self, *args, _original=original, _name=name):
            held[_name].append(box[0].lock.locked())
            return _original(self, *args)
        monkeypatch.setattr(Cm1Module, name, spy)
    before = sys.getswitchinterval()
    with enip_service() as st:
        box.append(st.transports[0])
        assert sys.getswitchinterval() <= SWITCH_INTERVAL + 2e-6   # kept in whole us
        tcp_port, io_port = ports(st)
        with socket.create_connection(("127.0.0.1", tcp_port), timeout=3) as tcp, \
                socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
            tcp.sendall(frame(enc.REGISTER_SESSION, struct.pack("<HH", 1, 0)).encode())
            handle = decode(tcp.recv(1024)).session
            request = forward_open(rpi=2_000, multiplier=7)
            tcp.sendall(frame(enc.SEND_RR_DATA, rr_data(request), handle).encode())
            reply = enc.parse_cpf(decode(tcp.recv(1024)).data[6:])[1].data
            assert reply[2] == 0, reply.hex()
            ot_id = struct.unpack_from("<I", reply, 4)[0]
            for count in range(1, 6):
                out.sendto(o_t(ot_id, count, count,
                               struct.pack("<HiihBB", 1, 100 * count, 100, 100, 0, 0)),
                           ("127.0.0.1", io_port))
                time.sleep(0.02)
            assert wait_until(lambda: len(held["write_output"]) >= 5
                         and len(held["input_image"]) >= 20, 3), held
    assert abs(sys.getswitchinterval() - before) <= 2e-6
    # the first image is read by Forward_Open itself, before the connection produces
    assert not any(held["write_output"]) and not any(held["input_image"][1:])


def test_adapter_closes_completely_with_class1_running(caplog):
    """Stopping the service while T->O packets flow ends the producer thread, closes the
    connections and frees the TCP, UDP 44818 and I/O ports; nothing is logged as failed."""
    from coolmuscle.frontends.enip.cip import encapsulation as enc
    from test_enip_encapsulation import decode, forward_open, frame, rr_data
    with enip_service() as st:
        transport = st.transports[0]
        tcp_port, io_port = ports(st)
        with socket.create_connection(("127.0.0.1", tcp_port), timeout=3) as tcp:
            tcp.sendall(frame(enc.REGISTER_SESSION, struct.pack("<HH", 1, 0)).encode())
            handle = decode(tcp.recv(1024)).session
            tcp.sendall(frame(enc.SEND_RR_DATA, rr_data(forward_open(rpi=2_000, multiplier=7)),
                              handle).encode())
            assert enc.parse_cpf(decode(tcp.recv(1024)).data[6:])[1].data[2] == 0
            producer = transport.producer
            assert wait_until(lambda: producer.sent > 10, 2)
    assert not producer.is_alive() and transport.producer is None
    assert transport.table.by_triad == {}
    assert not [r for r in caplog.records if r.levelname in ("ERROR", "CRITICAL")]
    for kind, port in ((socket.SOCK_STREAM, tcp_port), (socket.SOCK_DGRAM, tcp_port),
                       (socket.SOCK_DGRAM, io_port)):
        with socket.socket(socket.AF_INET, kind) as again:
            again.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            again.bind(("127.0.0.1", port))


def test_more_tcp_clients_than_the_bound_are_closed_and_the_rest_served(monkeypatch):
    """At most MAX_TCP_CLIENTS encapsulation clients at once (docs/reliability.md
    "Bounds"): one more is closed as it arrives, the others keep their sessions."""
    from coolmuscle.frontends.enip import server as enip_server
    from coolmuscle.frontends.enip.cip import encapsulation as enc
    from test_enip_encapsulation import decode, frame
    monkeypatch.setattr(enip_server, "MAX_TCP_CLIENTS", 4)
    with enip_service() as st:
        tcp_port, _ = ports(st)
        held = [socket.create_connection(("127.0.0.1", tcp_port), timeout=3) for _ in range(4)]
        try:
            for sock in held:
                sock.sendall(frame(enc.REGISTER_SESSION, struct.pack("<HH", 1, 0)).encode())
                assert decode(sock.recv(1024)).status == 0
            with socket.create_connection(("127.0.0.1", tcp_port), timeout=3) as extra:
                extra.sendall(frame(enc.REGISTER_SESSION, struct.pack("<HH", 1, 0)).encode())
                try:
                    assert extra.recv(1024) == b""
                except ConnectionResetError:
                    pass
            held[0].sendall(frame(enc.LIST_IDENTITY, b"").encode())    # still served
            assert decode(held[0].recv(1024)).status == 0
        finally:
            for sock in held:
                sock.close()


def _raw_open(tcp_port: int, request: bytes) -> tuple[int, tuple[int, ...]]:
    """A Forward_Open by hand (CIP Vol 1 3-5.5.2 bytes) on a session of its own: the
    general status and the extended status words of the reply."""
    from coolmuscle.frontends.enip.cip import encapsulation as enc
    from test_enip_encapsulation import decode, frame, rr_data
    with socket.create_connection(("127.0.0.1", tcp_port), timeout=3) as tcp:
        tcp.sendall(frame(enc.REGISTER_SESSION, struct.pack("<HH", 1, 0)).encode())
        handle = decode(tcp.recv(1024)).session
        tcp.sendall(frame(enc.SEND_RR_DATA, rr_data(request), handle).encode())
        reply = enc.parse_cpf(decode(tcp.recv(1024)).data[6:])[1].data
    return reply[2], struct.unpack_from(f"<{reply[3]}H", reply, 4)


def test_idle_class3_connections_never_keep_the_plcs_class1_out(monkeypatch):
    """EDS [Capacity]: MaxMsgConnections 3, MaxIOConnections 1, counted apart.  An idle
    client tries four class 3 connections with pycomm3 (one CIPDriver each, its
    Large_Forward_Open): three open, the fourth is refused.  The PLC (the ``ethernetip``
    package's Class 1 originator) still opens its exclusive owner and T->O flows.  By
    hand, one more class 3 request gets 0x01/0x0113 (out of connections, CIP Vol 1
    table 3-5.33) and a second Class 1 owner 0x01/0x0106 (ownership conflict)."""
    from pycomm3.exceptions import ResponseError

    from test_enip_encapsulation import class3_open, forward_open
    with enip_service() as st:
        tcp_port, io_port = ports(st)
        idle: list[CIPDriver] = []
        opened = []
        try:
            for _ in range(4):
                d = CIPDriver(f"127.0.0.1:{tcp_port}")
                d.open()
                idle.append(d)
                try:
                    opened.append(get(d, 1, 1, 7, connected=True).error is None)
                except ResponseError:             # pycomm3: "Target did not connected"
                    opened.append(False)
            scanner = _Scanner(monkeypatch, tcp_port, io_port)
            try:
                assert scanner.forward_open() == 0
                assert wait_until(lambda: len(scanner.times) > 5, 2)        # T->O flows
                assert opened == [True, True, True, False]
                assert _raw_open(tcp_port, class3_open(21)) == (0x01, (0x0113,))
                assert _raw_open(tcp_port, forward_open(serial=22)) == (0x01, (0x0106,))
                assert (st.transports[0].table.count(io=False),
                        st.transports[0].table.count(io=True)) == (3, 1)
            finally:
                scanner.close()
        finally:
            for d in idle:
                d.close()


def _closed_within(sock: socket.socket, limit: float) -> float | None:
    """Seconds until the adapter closes ``sock``; ``None`` if still open after ``limit``."""
    start = time.monotonic()
    sock.settimeout(limit)
    try:
        data = sock.recv(1024)
    except TimeoutError:
        return None
    except ConnectionResetError:
        data = b""
    assert data == b"", data
    return time.monotonic() - start


def test_encapsulation_inactivity_timeout_closes_silent_connections_cip_vol2_5_3():
    """TCP/IP attribute 13 set to 1 s with pycomm3: a connection that never sends and an
    idle pycomm3 client holding a class 3 connection are closed after about 1 s (the
    class 3 place is freed); a client sending NOP every 0.25 s stays.  Set to 0, an idle
    connection stays open."""
    from coolmuscle.frontends.enip.cip import encapsulation as enc
    from test_enip_encapsulation import decode, frame
    with enip_service() as st:
        tcp_port, _ = ports(st)
        table = st.transports[0].table
        with driver(st) as d:
            assert get(d, 0xF5, 1, 13).value == struct.pack("<H", 120)
            assert generic_status(d, service=0x10, class_code=0xF5, instance=1, attribute=13,
                                  request_data=struct.pack("<H", 3601)) == 0x09
            assert set_(d, 0xF5, 1, 13, struct.pack("<H", 1)).error is None
            assert get(d, 0xF5, 1, 13).value == struct.pack("<H", 1)
        holder = CIPDriver(f"127.0.0.1:{tcp_port}")
        holder.open()
        assert get(holder, 1, 1, 7, connected=True).error is None
        assert table.count(io=False) == 1
        talker = socket.create_connection(("127.0.0.1", tcp_port), timeout=3)
        silent = socket.create_connection(("127.0.0.1", tcp_port), timeout=3)
        try:
            started, closed = time.monotonic(), None
            while time.monotonic() - started < 2.5:
                talker.sendall(frame(enc.NOP, b"").encode())
                if closed is None:
                    waited = _closed_within(silent, 0.25)
                    if waited is not None:
                        closed = time.monotonic() - started
                else:
                    time.sleep(0.25)
            assert closed is not None and 0.7 <= closed <= 2.0, closed
            assert wait_until(lambda: table.count(io=False) == 0, 1)        # holder's place
            talker.sendall(frame(enc.LIST_IDENTITY, b"").encode())
            assert decode(talker.recv(1024)).status == 0                 # talker stays
            assert st.transports[0].idle_closed == 2
        finally:
            talker.close()
            silent.close()
            try:
                holder.close()
            except Exception:       # pycomm3 cannot say goodbye on a closed socket
                pass
        with driver(st) as d:
            assert set_(d, 0xF5, 1, 13, struct.pack("<H", 0)).error is None
        with socket.create_connection(("127.0.0.1", tcp_port), timeout=3) as quiet:
            assert _closed_within(quiet, 1.5) is None                    # 0: never
