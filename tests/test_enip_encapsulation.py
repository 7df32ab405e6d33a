"""Encapsulation, CIP and connection rules, sans-IO (CIP Vol 1 ch. 2-3, Vol 2 ch. 2-3), and fuzzing.

The encapsulation layer is fed bytes and answers bytes; the CIP side is the real
router in front of a virtual CM1 in virtual time.  The fuzz tests feed random and
mutated packets (truncated, wrong lengths, flipped bytes) and check that nothing
raises, nothing hangs, and another client's session is untouched.
"""

from __future__ import annotations

import socket
import struct
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coolmuscle.chain import Chain
from coolmuscle.frontends.enip.cip import connmgr
from coolmuscle.frontends.enip.cip import encapsulation as enc
from coolmuscle.frontends.enip.cip import messages as cip
from coolmuscle.frontends.enip.cip.io import ConnectionTable, multicast_address
from coolmuscle.frontends.enip.cip.router import Router
from coolmuscle.frontends.enip.cm1.adapter import Cm1Module
from coolmuscle.frontends.enip.cm1.objects import DESCRIPTION, ObjectModel
from coolmuscle.sim.kernel import Kernel
from enip_support import enip_service, ports

PEER = ("127.0.0.1", 50000)
LOCAL = ("127.0.0.1", 44818)


class Rig:
    """A router over a virtual CM1, with a settable clock (ns)."""

    def __init__(self) -> None:
        self.kernel = Kernel()
        self.chain = Chain(self.kernel, motors=1, firmware="cm1", state_dir=None)
        self.module = Cm1Module(self.chain)
        self.now = 1_000_000_000
        self.table = ConnectionTable(self.module, DESCRIPTION, "127.0.0.1", 2222)
        objects = ObjectModel(self.module, output_owned=lambda: self.table.owner is not None)
        self.router = Router(objects, self.table, 44818, clock=lambda: self.now)
        self.sessions = enc.Sessions()

    def connection(self) -> enc.Connection:
        return enc.Connection(self.router, self.sessions, PEER, LOCAL)


@pytest.fixture
def rig():
    r = Rig()
    yield r
    r.chain.close()


def frame(command: int, data: bytes = b"", session: int = 0, context: bytes = b"ctx12345",
          status: int = 0, options: int = 0) -> enc.Frame:
    return enc.Frame(command, session, status, context, options, data)


def decode(reply: bytes) -> enc.Frame:
    got = enc.decode_frame(reply)
    assert got is not None
    return got


def register(conn: enc.Connection) -> int:
    reply = decode(conn.handle(frame(enc.REGISTER_SESSION, struct.pack("<HH", 1, 0)))
                   or b"")
    assert reply.status == 0 and reply.session
    return reply.session


def rr_data(cip_request: bytes, extra: list[enc.Item] = ()) -> bytes:
    items = [enc.Item(enc.ITEM_NULL), enc.Item(enc.ITEM_UNCONNECTED_DATA, cip_request), *extra]
    return struct.pack("<IH", 0, 0) + enc.encode_cpf(items)


def cip_reply(reply: bytes) -> bytes:
    items = enc.parse_cpf(decode(reply).data[6:])
    return items[1].data


def get_request(cls: int, inst: int, attr: int) -> bytes:
    path = cip.encode_path(cls, inst, attr)
    return bytes((0x0E, len(path) // 2)) + path


def forward_open(rpi: int = 10_000, ot_size: int = 20, to_size: int = 10, serial: int = 1,
                 key: bytes = b"", to_type: int = 2, transport: int = 0x01, multiplier: int = 2,
                 path: bytes = bytes.fromhex("20 04 24 80 2C 66 2C 65")) -> bytes:
    """A Forward_Open request (service 0x54 to 06/01) as a scanner sends it."""
    conn_path = key + path
    ot = ot_size | (2 << 13)
    to = to_size | (to_type << 13)
    body = struct.pack("<BBIIHHIB3xIHIHBB", 0x0A, 0xF0, 0, 0x1234_0000 + serial, serial,
                       0x00FE, 0xDEAD0000, multiplier, rpi, ot, rpi, to, transport,
                       len(conn_path) // 2) + conn_path
    return bytes((0x54, 2, 0x20, 0x06, 0x24, 0x01)) + body


# -- encapsulation (CIP Vol 2 2-3 .. 2-5) ------------------------------------------------
def test_vol2_unknown_command_status_0x0001_context_echoed(rig):
    reply = decode(rig.connection().handle(frame(0x00AB, b"xy")))
    assert (reply.command, reply.status, reply.context) == (0x00AB, 0x0001, b"ctx12345")


def test_vol2_register_session_rules(rig):
    conn = rig.connection()
    assert decode(conn.handle(frame(enc.REGISTER_SESSION, b"\x01\x00\x00"))).status == 0x0065
    bad = decode(conn.handle(frame(enc.REGISTER_SESSION, struct.pack("<HH", 2, 0))))
    assert bad.status == 0x0069 and bad.data == struct.pack("<HH", 1, 0)
    flagged = decode(conn.handle(frame(enc.REGISTER_SESSION, struct.pack("<HH", 1, 1))))
    assert flagged.status == 0x0069 and flagged.session == 0 and conn.session == 0
    handle = register(conn)
    again = decode(conn.handle(frame(enc.REGISTER_SESSION, struct.pack("<HH", 1, 0))))
    assert again.status == 0x0003 and conn.session == handle


def test_vol2_send_rr_data_needs_this_connections_session(rig):
    a, b = rig.connection(), rig.connection()
    ha = register(a)
    request = rr_data(get_request(4, 0x65, 3))
    assert decode(b.handle(frame(enc.SEND_RR_DATA, request))).status == 0x0064
    assert decode(b.handle(frame(enc.SEND_RR_DATA, request, session=ha))).status == 0x0064
    ok = decode(a.handle(frame(enc.SEND_RR_DATA, request, session=ha)))
    assert ok.status == 0 and cip_reply(ok.encode())[:4] == b"\x8e\x00\x00\x00"


def test_vol2_nop_and_nonzero_options_get_no_reply(rig):
    conn = rig.connection()
    assert conn.handle(frame(enc.NOP, b"anything")) is None
    assert conn.handle(frame(enc.LIST_IDENTITY, options=1)) is None


def test_vol2_unregister_closes_and_frees_the_session(rig):
    conn = rig.connection()
    handle = register(conn)
    assert conn.handle(frame(enc.UNREGISTER_SESSION, session=handle)) is None
    assert conn.closing and handle not in rig.sessions.active


def test_vol2_bad_common_packet_format_is_incorrect_data(rig):
    conn = rig.connection()
    handle = register(conn)
    broken = struct.pack("<IH", 0, 0) + struct.pack("<HHH", 2, 0, 0)   # 2 items, 1 there
    assert decode(conn.handle(frame(enc.SEND_RR_DATA, broken, handle))).status == 0x0003
    assert decode(conn.handle(frame(enc.SEND_RR_DATA, b"\x00", handle))).status == 0x0065


def test_vol2_frame_reader_lengths():
    reader = enc.FrameReader()
    one = frame(enc.NOP, b"abc").encode()
    reader.receive_data(one + one[:10])
    assert reader.next_frame().data == b"abc" and reader.next_frame() is None
    reader.receive_data(one[10:])
    assert reader.next_frame().data == b"abc"
    reader.receive_data(struct.pack("<HHII8sI", 0x6F, 60000, 0, 0, bytes(8), 0))
    with pytest.raises(enc.FramingError):
        reader.next_frame()


def test_vol2_list_commands_over_udp(rig):
    ident = enc.answer_datagram(frame(enc.LIST_IDENTITY).encode(), rig.router, LOCAL)
    items = enc.parse_cpf(decode(ident).data)
    assert items[0].type_id == enc.ITEM_IDENTITY and b"Cool Muscle 1" in items[0].data
    services = enc.parse_cpf(decode(enc.answer_datagram(
        frame(enc.LIST_SERVICES).encode(), rig.router, LOCAL)).data)
    assert struct.unpack_from("<HH", services[0].data) == (1, 0x0120)
    assert decode(enc.answer_datagram(frame(enc.LIST_INTERFACES).encode(), rig.router,
                                      LOCAL)).data == b"\x00\x00"
    assert enc.answer_datagram(frame(enc.REGISTER_SESSION, b"\x01\x00\x00\x00").encode(),
                               rig.router, LOCAL) is None


# -- Connection Manager (CIP Vol 1 3-5.5, table 3-5.33) ------------------------------------
def open_via(rig, conn, handle, request: bytes):
    reply = cip_reply(conn.handle(frame(enc.SEND_RR_DATA, rr_data(request), handle)))
    status, size = reply[2], reply[3]
    extended = struct.unpack_from(f"<{size}H", reply, 4) if size else ()
    return status, extended, reply[4 + 2 * size:]


@pytest.mark.parametrize("kw, extended", [
    (dict(rpi=1_000), 0x0111),                                 # below 2 ms
    (dict(ot_size=22), 0x0127),
    (dict(to_size=12), 0x0128),
    (dict(key=bytes.fromhex("34 04 01 00 2B 00 01 00 01 07")), 0x0114),   # vendor 1
    (dict(path=bytes.fromhex("20 04 24 80 2C 70 2C 65")), 0x012A),
    (dict(path=bytes.fromhex("20 04 24 81 2C 66 2C 65")), 0x0129),
    (dict(transport=0x21), 0x0103),
    (dict(path=bytes.fromhex("20 04 24 80 2C 66 2C 65 80 01 00 00")), 0x0126),
], ids=["rpi", "ot-size", "to-size", "key", "consuming", "config", "transport", "config-data"])
def test_vol1_forward_open_refusals(rig, kw, extended):
    conn = rig.connection()
    status, ext, body = open_via(rig, conn, register(conn), forward_open(**kw))
    assert status == 0x01 and ext[0] == extended
    assert struct.unpack_from("<HHI", body) == (1, 0x00FE, 0xDEAD0000)   # the triad


def test_vol1_duplicate_owner_and_close(rig):
    conn = rig.connection()
    handle = register(conn)
    assert open_via(rig, conn, handle, forward_open())[0] == 0
    assert open_via(rig, conn, handle, forward_open())[1] == (0x0100,)
    assert open_via(rig, conn, handle, forward_open(serial=2))[1] == (0x0106,)
    close = bytes((0x4E, 2, 0x20, 0x06, 0x24, 0x01)) + struct.pack(
        "<BBHHIBB", 0x0A, 0xF0, 1, 0x00FE, 0xDEAD0000, 0, 0)
    assert open_via(rig, conn, handle, close)[0] == 0
    assert open_via(rig, conn, handle, close)[1] == (0x0107,)


def class3_open(serial: int) -> bytes:
    """A class 3 Forward_Open to the Message Router (20 02 24 01), as pycomm3 sends one."""
    return forward_open(serial=serial, ot_size=504, to_size=504, transport=0xA3,
                        path=bytes.fromhex("20 02 24 01"))


def test_eds_capacity_per_kind_class3_never_starves_class1(rig):
    """EDS [Capacity]: MaxMsgConnections 3, MaxIOConnections 1.  Four class 3 requests
    from one idle client: three open, the fourth is out of connections (0x0113); the
    PLC's Class 1 exclusive owner still opens; a second one is an ownership conflict
    (0x0106).  Closing a class 3 connection frees its place for another."""
    client = rig.connection()
    handle = register(client)
    class3 = [open_via(rig, client, handle, class3_open(serial)) for serial in (11, 12, 13, 14)]
    plc = rig.connection()
    plc_handle = register(plc)
    assert open_via(rig, plc, plc_handle, forward_open(serial=1))[0] == 0      # Class 1
    assert [status for status, _e, _b in class3] == [0, 0, 0, 0x01]
    assert class3[3][1] == (0x0113,)
    assert open_via(rig, plc, plc_handle, forward_open(serial=2))[1] == (0x0106,)
    assert (rig.table.count(io=False), rig.table.count(io=True)) == (3, 1)
    close = bytes((0x4E, 2, 0x20, 0x06, 0x24, 0x01)) + struct.pack(
        "<BBHHIBB", 0x0A, 0xF0, 11, 0x00FE, 0xDEAD0000, 0, 0)
    assert open_via(rig, client, handle, close)[0] == 0
    assert open_via(rig, client, handle, class3_open(15))[0] == 0


def test_message_router_and_eds_say_the_same_capacity(rig):
    from coolmuscle.frontends.enip.cm1.eds import generate
    conn = rig.connection()
    reply = cip_reply(conn.handle(frame(enc.SEND_RR_DATA, rr_data(get_request(2, 1, 2)),
                                        register(conn))))
    assert reply[2] == 0 and struct.unpack_from("<H", reply, 4)[0] == 3
    eds = generate()
    assert "MaxIOConnections = 1;" in eds and "MaxMsgConnections = 3;" in eds


def test_vol1_modeless_output_accepted_and_key_wildcards(rig):
    conn = rig.connection()
    key = bytes.fromhex("34 04 00 00 00 00 00 00 00 00")
    status, _, body = open_via(rig, conn, register(conn), forward_open(ot_size=16, key=key))
    assert status == 0 and not rig.table.owner.header
    assert struct.unpack_from("<I", body, 16)[0] == 10_000        # O->T API = RPI


# -- Class 1 data (CIP Vol 1 3-4; manual 3.2) ----------------------------------------------------
def o_t(conn_id: int, seq: int, count: int, data: bytes, run: bool = True) -> bytes:
    body = struct.pack("<H", count) + struct.pack("<I", int(run)) + data
    return enc.encode_cpf([enc.Item(enc.ITEM_SEQUENCED_ADDRESS, struct.pack("<II", conn_id, seq)),
                           enc.Item(enc.ITEM_CONNECTED_DATA, body)])


def opened(rig) -> int:
    conn = rig.connection()
    status, _, body = open_via(rig, conn, register(conn), forward_open())
    assert status == 0
    return struct.unpack_from("<I", body)[0]


def test_class1_consume_rules(rig):
    ot_id = opened(rig)
    data = struct.pack("<HiihBB", 1, 0, 100, 100, 0, 1)
    assert not rig.table.consume(o_t(ot_id, 1, 1, data), "10.0.0.9", rig.now)   # other host
    assert not rig.table.consume(o_t(ot_id + 1, 1, 1, data), PEER[0], rig.now)  # unknown id
    assert not rig.table.consume(o_t(ot_id, 1, 1, data[:-1]), PEER[0], rig.now)  # size
    assert rig.table.consume(o_t(ot_id, 5, 1, data), PEER[0], rig.now)
    assert rig.chain.get_param(1, 52) == 10                                       # applied
    assert not rig.table.consume(o_t(ot_id, 4, 2, data), PEER[0], rig.now)       # older
    rig.chain.set_param(1, 52, 0)
    assert rig.table.consume(o_t(ot_id, 6, 1, data), PEER[0], rig.now)           # same count
    assert rig.chain.get_param(1, 52) == 0                                        # not new data


def test_class1_production_sequence_and_timeout(rig):
    ot_id = opened(rig)
    rig.table.consume(o_t(ot_id, 1, 1, struct.pack("<HiihBB", 1, 0, 100, 100, 0, 0)),
                      PEER[0], rig.now)
    packets = []
    for step in range(5):
        packets += rig.table.due(rig.now + step * 10_000_000)
    seqs = [struct.unpack_from("<II", enc.parse_cpf(p)[0].data)[1] for p, _ in packets]
    counts = [struct.unpack_from("<H", enc.parse_cpf(p)[1].data)[0] for p, _ in packets]
    assert seqs == [1, 2, 3, 4, 5] and counts == [1, 2, 3, 4, 5]
    assert all(addr == (PEER[0], 2222) for _, addr in packets)
    assert enc.parse_cpf(packets[0][0])[1].data[2:] == rig.module.input_image()
    assert not rig.table.expire(rig.now + 16 * 10_000_000)          # multiplier 2: x16
    assert rig.table.expire(rig.now + 16 * 10_000_000 + 1)
    assert rig.table.owner is None and rig.module.output_image() == bytes(14)


def test_vol2_multicast_address_of_3_5_3(rig):
    assert multicast_address("127.0.0.1") == "239.192.1.0"
    assert multicast_address("192.168.1.10") == "239.192.2.32"
    conn = rig.connection()
    handle = register(conn)
    reply = conn.handle(frame(enc.SEND_RR_DATA, rr_data(forward_open(to_type=1)), handle))
    items = enc.parse_cpf(decode(reply).data[6:])
    to_item = next(i for i in items if i.type_id == enc.ITEM_SOCKADDR_TO)
    assert enc.parse_sockaddr(to_item.data) == (2222, 0xEFC00100)
    assert rig.table.owner.to_addr == ("239.192.1.0", 2222)


def test_set_output_refused_while_a_connection_owns_it(rig):
    opened(rig)
    conn = rig.connection()
    handle = register(conn)
    path = cip.encode_path(4, 0x66, 3)
    request = bytes((0x10, len(path) // 2)) + path + bytes(14)
    reply = cip_reply(conn.handle(frame(enc.SEND_RR_DATA, rr_data(request), handle)))
    assert reply[2] == cip.DEVICE_STATE_CONFLICT


# -- fuzzing ------------------------------------------------------------------------------------
def _valid_requests(handle: int) -> list[bytes]:
    return [frame(enc.REGISTER_SESSION, struct.pack("<HH", 1, 0)).encode(),
            frame(enc.SEND_RR_DATA, rr_data(get_request(4, 0x65, 3)), handle).encode(),
            frame(enc.SEND_RR_DATA, rr_data(forward_open(serial=9)), handle).encode(),
            frame(enc.LIST_IDENTITY).encode(),
            frame(enc.SEND_UNIT_DATA, struct.pack("<IH", 0, 0) + enc.encode_cpf([
                enc.Item(enc.ITEM_CONNECTED_ADDRESS, b"\x01\x02\x03\x04"),
                enc.Item(enc.ITEM_CONNECTED_DATA, b"\x01\x00" + get_request(1, 1, 1))]),
                handle).encode()]


def _mutate(data: bytes, how: int, at: int, value: int) -> bytes:
    if not data:
        return data
    at %= len(data)
    if how == 0:
        return data[:at]                                            # truncated
    if how == 1:
        return data[:at] + bytes((value,)) + data[at + 1:]          # one byte changed
    if how == 2:
        return data[:2] + struct.pack("<H", value * 257) + data[4:]  # wrong length
    return data + bytes((value,)) * (at % 7)                        # extra bytes


def _feed(conn: enc.Connection, data: bytes) -> None:
    reader = enc.FrameReader()
    reader.receive_data(data)
    while not conn.closing:
        try:
            got = reader.next_frame()
        except enc.FramingError:
            return
        if got is None:
            return
        conn.handle(got)


FUZZ = settings(max_examples=300, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


@FUZZ
@given(st.binary(max_size=200))
def test_fuzz_random_bytes_never_raise(rig, data):
    victim = rig.connection()
    handle = register(victim)
    attacker = rig.connection()
    _feed(attacker, data)
    reply = decode(victim.handle(frame(enc.SEND_RR_DATA, rr_data(get_request(1, 1, 1)), handle)))
    assert reply.status == 0 and victim.session == handle and handle in rig.sessions.active
    attacker.close()
    victim.close()


@FUZZ
@given(st.integers(0, 4), st.integers(0, 3), st.integers(0, 10_000), st.integers(0, 255),
       st.integers(1, 3))
def test_fuzz_mutated_packets_leave_other_session_alone(rig, which, how, at, value, times):
    victim = rig.connection()
    handle = register(victim)
    attacker = rig.connection()
    attacker_handle = register(attacker)
    packet = _valid_requests(attacker_handle)[which]
    _feed(attacker, _mutate(packet, how, at, value) * times)
    for request in (get_request(4, 0x65, 3), get_request(1, 1, 7)):
        reply = decode(victim.handle(frame(enc.SEND_RR_DATA, rr_data(request), handle)))
        assert reply.status == 0 and cip_reply(reply.encode())[2] == 0
    assert handle in rig.sessions.active
    attacker.close()
    victim.close()
    rig.table.close_all()


@FUZZ
@given(st.binary(max_size=80))
def test_fuzz_cip_parsers_raise_only_cip_errors(rig, data):
    for parse in (cip.parse_request, cip.parse_path,
                  lambda d: connmgr.parse_open(d, False), lambda d: connmgr.parse_open(d, True),
                  connmgr.parse_close):
        try:
            parse(data)
        except cip.CipError:
            pass
    reply = rig.router.unconnected(data, enc.Peer(1, PEER, LOCAL))[0]
    assert reply == b"" or reply[0] & 0x80 or not data
    rig.table.consume(data, PEER[0], rig.now)


def test_fuzz_live_server_other_client_untouched():
    """Garbage over real sockets (TCP 44818-style and UDP I/O) while a pycomm3 client works."""
    import random

    from pycomm3 import CIPDriver
    rng = random.Random(13)
    with enip_service() as service:
        tcp_port, io_port = ports(service)
        with CIPDriver(f"127.0.0.1:{tcp_port}") as good:
            packets = _valid_requests(0x1234)
            for i in range(60):
                with socket.create_connection(("127.0.0.1", tcp_port), timeout=2) as bad:
                    blob = _mutate(rng.choice(packets), rng.randrange(4),
                                   rng.randrange(10_000), rng.randrange(256))
                    bad.sendall(blob + bytes(rng.randrange(256) for _ in range(i % 9)))
                udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                udp.sendto(bytes(rng.randrange(256) for _ in range(rng.randrange(40))),
                           ("127.0.0.1", io_port if i % 2 else tcp_port))
                udp.close()
            time.sleep(0.2)
            tag = good.generic_message(service=0x0E, class_code=4, instance=0x65, attribute=3,
                                       connected=False, route_path=False)
            assert tag.error is None and len(tag.value) == 8
        assert service.transports[0].router.failures == 0     # nothing failed inside


def test_identity_reset_closes_connections_and_clears_outputs(rig):
    """CIP Vol 1 5A-2.3 Reset type 0: the module restarts; the motor is not reset."""
    opened(rig)
    rig.module.write_output(struct.pack("<HiihBB", 1, 0, 100, 100, 0, 1), True)
    rig.router.objects.reset = lambda: (rig.table.close_all(), rig.module.reset_outputs())
    conn = rig.connection()
    handle = register(conn)
    path = cip.encode_path(1, 1)
    reset = bytes((0x05, len(path) // 2)) + path
    reply = cip_reply(conn.handle(frame(enc.SEND_RR_DATA, rr_data(reset + b"\x00"), handle)))
    assert reply[:4] == b"\x85\x00\x00\x00"
    assert rig.table.owner is None and rig.module.output_image() == bytes(14)
    bad = cip_reply(conn.handle(frame(enc.SEND_RR_DATA, rr_data(reset + b"\x05"), handle)))
    assert bad[2] == cip.INVALID_PARAMETER


# -- TCP/IP Interface attribute 13, the encapsulation inactivity timeout (CIP Vol 2 5-3) --
def _cip(conn: enc.Connection, handle: int, request: bytes) -> tuple[int, bytes]:
    reply = cip_reply(conn.handle(frame(enc.SEND_RR_DATA, rr_data(request), handle)))
    return reply[2], reply[4 + 2 * reply[3]:]


def set_request(cls: int, inst: int, attr: int, data: bytes) -> bytes:
    path = cip.encode_path(cls, inst, attr)
    return bytes((0x10, len(path) // 2)) + path + data


def test_vol2_inactivity_timeout_get_set_range_and_out_of_box_reset(rig):
    conn = rig.connection()
    handle = register(conn)
    assert _cip(conn, handle, get_request(0xF5, 1, 13)) == (0, struct.pack("<H", 120))
    all_before = _cip(conn, handle, bytes((0x01, 2)) + cip.encode_path(0xF5, 1))
    for value, status in ((3601, 0x09), (0xFFFF, 0x09), (3600, 0), (0, 0), (1, 0)):
        assert _cip(conn, handle, set_request(0xF5, 1, 13, struct.pack("<H", value)))[0] \
            == status, value
    assert _cip(conn, handle, set_request(0xF5, 1, 13, b"\x05"))[0] == 0x13
    assert _cip(conn, handle, set_request(0xF5, 1, 13, b"\x05\x00\x01"))[0] == 0x15
    assert _cip(conn, handle, set_request(0xF5, 1, 13, b"\x07\x00\x00\x00"))[0] == 0  # + route
    assert _cip(conn, handle, get_request(0xF5, 1, 13)) == (0, struct.pack("<H", 7))
    assert rig.router.objects.inactivity.seconds == 7
    assert _cip(conn, handle, bytes((0x01, 2)) + cip.encode_path(0xF5, 1)) == all_before
    path = cip.encode_path(1, 1)
    assert _cip(conn, handle, bytes((0x05, len(path) // 2)) + path + b"\x00")[0] == 0
    assert rig.router.objects.inactivity.seconds == 7         # type 0: a power cycle
    assert _cip(conn, handle, bytes((0x05, len(path) // 2)) + path + b"\x01")[0] == 0
    assert rig.router.objects.inactivity.seconds == 120       # type 1: out of box
