"""The sans-IO ESC, state machine and CoE server, fed frames and mailboxes directly.

ETG.1000.4 datagram and working-counter rules; manual 2.3 (SM/FMMU layout), 5.2
(ESM and AL status codes), 5.4.1 (abort codes).
"""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coolmuscle.frontends.ethercat.bridge import identity as ident
from coolmuscle.frontends.ethercat.bridge.app import BridgeApp
from coolmuscle.frontends.ethercat.bridge.table import build_table
from coolmuscle.frontends.ethercat.engine import esc as E
from coolmuscle.frontends.ethercat.engine import esm
from coolmuscle.frontends.ethercat.engine.coe import CoeServer
from coolmuscle.frontends.ethercat.engine.dictionary import Dictionary
from ethercat_support import MAC, datagrams, frame


@pytest.fixture
def app() -> BridgeApp:
    return BridgeApp(None)


def one(app: BridgeApp, cmd: int, adp: int, ado: int, data: bytes) -> tuple[int, bytes, int]:
    out = app.stack.esc.process(frame((cmd, adp, ado, data)))
    assert out is not None
    c, a, d, w = datagrams(out)[0]
    return a, d, w


def set_station(app: BridgeApp, station: int = 0x1001) -> None:
    one(app, E.APWR, 0, E.REG_STATION, struct.pack("<H", station))


def configure_mailbox(app: BridgeApp) -> None:
    set_station(app)
    for n, (start, size, ctl) in enumerate(((ident.MBX_OUT_START, ident.MBX_OUT_SIZE, 0x26),
                                            (ident.MBX_IN_START, ident.MBX_IN_SIZE, 0x22))):
        one(app, E.FPWR, 0x1001, E.REG_SM + 8 * n, struct.pack("<HHBBBB", start, size, ctl,
                                                                0, 1, 0))


def request_state(app: BridgeApp, value: int) -> int:
    one(app, E.FPWR, 0x1001, E.REG_AL_CONTROL, struct.pack("<H", value))
    return app.stack.esc.al_status


# -- datagrams and working counters (ETG.1000.4) ------------------------------
def test_auto_increment_reads_only_at_position_zero_and_increments_adp():
    a = BridgeApp(None)
    adp, data, wkc = one(a, E.APRD, 0, 0x0000, bytes(2))
    assert (adp, wkc, data[0]) == (1, 1, 0x98)
    adp, data, wkc = one(a, E.APRD, 0xFFFF, 0x0000, bytes(2))   # the next slave's
    assert (adp, wkc, data) == (0, 0, bytes(2))


def test_fixed_address_only_for_our_station_and_frames_of_others_pass_untouched(app):
    set_station(app, 0x1001)
    assert app.stack.esc.station == 0x1001
    assert one(app, E.FPRD, 0x1001, E.REG_STATION, bytes(2))[1:] == (b"\x01\x10", 1)
    request = frame((E.FPWR, 0x1002, E.REG_AL_CONTROL, b"\x08\x00"))
    out = app.stack.esc.process(request)
    assert out[14:] == request[14:] and app.stack.state == esm.INIT


def test_broadcast_read_ors_and_counts_and_write_counts(app):
    adp, data, wkc = one(app, E.BRD, 0, E.REG_AL_STATUS, b"\x10\x00")
    assert (data, wkc, adp) == (b"\x11\x00", 1, 1)
    assert one(app, E.BWR, 0, 0x0300, bytes(8))[2] == 1


def test_read_write_counts_three_and_returns_the_old_value(app):
    set_station(app)
    _a, data, wkc = one(app, E.FPRW, 0x1001, E.REG_STATION, b"\x02\x10")
    assert (data, wkc, app.stack.esc.station) == (b"\x01\x10", 3, 0x1002)


def test_armw_reads_at_zero_and_writes_elsewhere_frmw_reads_at_station(app):
    set_station(app)
    assert one(app, E.ARMW, 0, E.REG_DC_SYSTIME, bytes(4))[2] == 1
    assert one(app, E.ARMW, 0xFFFF, 0x0300, bytes(4))[2] == 1
    assert one(app, E.FRMW, 0x1001, E.REG_STATION, bytes(2))[1:] == (b"\x01\x10", 1)


def test_read_only_registers_ignore_writes(app):
    one(app, E.APWR, 0, E.REG_TYPE, b"\x00")
    one(app, E.APWR, 0, E.REG_AL_STATUS, b"\x08\x00")
    assert app.stack.esc.mem[0] == 0x98 and app.stack.state == esm.INIT


def test_logical_read_write_counts_one_two_three(app):
    esc = app.stack.esc
    esc.mem[0x1180:0x1184] = b"\x00" * 4
    esc.set_inputs(3, bytes(range(1, 25)))
    for n, (log, phys, kind) in enumerate(((0x10000, 0x1100, 2), (0x10018, 0x1180, 1))):
        one(app, E.APWR, 0, E.REG_FMMU + 16 * n,
            struct.pack("<IHBBHBBB3x", log, 24, 0, 7, phys, 0, kind, 1))
    for n, (start, ctl) in enumerate(((0x1100, 0x64), (0x1180, 0x20))):
        one(app, E.APWR, 0, E.REG_SM + 8 * (n + 2), struct.pack("<HHBBBB", start, 24, ctl, 0, 1, 0))
    _a, data, wkc = one(app, E.LRW, 0x0000, 0x0001, bytes(range(100, 124)) + bytes(24))
    assert wkc == 3 and data[24:] == bytes(range(1, 25))
    assert bytes(esc.mem[0x1100:0x1118]) == bytes(range(100, 124))
    assert one(app, E.LRD, 0x0018, 0x0001, bytes(24))[2] == 1
    assert one(app, E.LWR, 0x0000, 0x0001, bytes(24))[2] == 1
    assert one(app, E.LRD, 0x0000, 0x0002, bytes(24))[2] == 0        # nobody maps it


def test_non_datagram_frames_pass_and_other_ethertypes_are_not_ours(app):
    other = MAC + struct.pack("<H", 0x4000 | 4) + b"abcd"
    assert app.stack.esc.process(other)[14:] == other[14:]
    assert app.stack.esc.process(b"\xff" * 12 + b"\x08\x00" + bytes(46)) is None


# -- SyncManager mailbox semantics ------------------------------------------------
def test_mailbox_full_refuses_a_second_write_and_empty_read_has_no_wkc(app):
    configure_mailbox(app)
    assert request_state(app, esm.PREOP) == esm.PREOP
    assert one(app, E.FPRD, 0x1001, ident.MBX_IN_START, bytes(128))[2] == 0   # empty
    sdo = struct.pack("<HHBB", 10, 0, 0, 0x13) + struct.pack("<H", 0x2000) + \
        struct.pack("<BHBI", 0x40, 0x1018, 1, 0)
    assert one(app, E.FPWR, 0x1001, ident.MBX_OUT_START, sdo.ljust(128, b"\0"))[2] == 1
    status = one(app, E.FPRD, 0x1001, E.REG_SM + 8 + 5, b"\0")[1][0]
    assert status & 0x08                                                    # SM1 full
    _a, answer, wkc = one(app, E.FPRD, 0x1001, ident.MBX_IN_START, bytes(128))
    assert wkc == 1 and struct.unpack_from("<I", answer, 12)[0] == ident.VENDOR_ID
    assert one(app, E.FPRD, 0x1001, ident.MBX_IN_START, bytes(128))[2] == 0  # read: empty


def test_mailbox_repeat_request_sends_the_last_answer_again(app):
    configure_mailbox(app)
    request_state(app, esm.PREOP)
    sdo = struct.pack("<HHBB", 10, 0, 0, 0x13) + struct.pack("<H", 0x2000) + \
        struct.pack("<BHBI", 0x40, 0x1000, 0, 0)
    one(app, E.FPWR, 0x1001, ident.MBX_OUT_START, sdo.ljust(128, b"\0"))
    first = one(app, E.FPRD, 0x1001, ident.MBX_IN_START, bytes(128))[1]
    one(app, E.FPWR, 0x1001, E.REG_SM + 8 + 6, b"\x03")                      # toggle repeat
    assert one(app, E.FPRD, 0x1001, E.REG_SM + 8 + 7, b"\0")[1][0] & 0x02    # repeat ack
    assert one(app, E.FPRD, 0x1001, ident.MBX_IN_START, bytes(128))[1:] == (first, 1)


# -- the state machine (5.2) -------------------------------------------------------
@pytest.mark.parametrize("frm,to,code", [(esm.INIT, esm.OP, 0x0011),
                                         (esm.INIT, esm.SAFEOP, 0x0011),
                                         (esm.PREOP, esm.OP, 0x0011),
                                         (esm.INIT, 5, 0x0012), (esm.INIT, esm.BOOT, 0x0013)])
def test_esm_refuses_with_the_5_2_2_code_and_sets_the_error_bit(frm, to, code):
    out = esm.request(frm, 0, to, lambda a, b: 0)
    assert (out.state, out.error, out.code) == (frm, True, code)


def test_esm_error_needs_an_acknowledge_before_going_up():
    refused = esm.request(esm.INIT, 0, esm.OP, lambda a, b: 0)
    stay = esm.request(refused.al_status, refused.code, esm.PREOP, lambda a, b: 0)
    assert (stay.state, stay.error, stay.code) == (esm.INIT, True, 0x0011)
    ok = esm.request(refused.al_status, refused.code, esm.PREOP | esm.ACK, lambda a, b: 0)
    assert (ok.state, ok.error, ok.code) == (esm.PREOP, False, 0)
    down = esm.request(esm.OP | esm.ERROR_FLAG, 0x1B, esm.INIT, lambda a, b: 0)
    assert down.state == esm.INIT


def test_preop_needs_the_mailbox_of_the_sii_0016(app):
    set_station(app)
    assert request_state(app, esm.PREOP) == esm.INIT | esm.ERROR_FLAG
    assert app.stack.esc.al_code == 0x0016


def test_safeop_checks_outputs_inputs_and_watchdog_001d_001e_001f(app):
    configure_mailbox(app)
    request_state(app, esm.PREOP)

    def sm(n: int, start: int, length: int, ctl: int) -> None:
        # deactivated first: an ESC keeps the settings of an activated SyncManager
        one(app, E.FPWR, 0x1001, E.REG_SM + 8 * n + 6, b"\x00")
        one(app, E.FPWR, 0x1001, E.REG_SM + 8 * n, struct.pack("<HHBBBB", start, length, ctl,
                                                                0, 1, 0))
    sm(2, 0x1100, 20, 0x64)
    sm(3, 0x1180, 24, 0x20)
    assert request_state(app, esm.SAFEOP | esm.ACK) & 0x1F == esm.PREOP | esm.ERROR_FLAG
    assert app.stack.esc.al_code == 0x001D
    sm(2, 0x1100, 24, 0x64)
    sm(3, 0x1180, 12, 0x20)
    request_state(app, esm.SAFEOP | esm.ACK)
    assert app.stack.esc.al_code == 0x001E
    sm(3, 0x1180, 24, 0x20)
    one(app, E.FPWR, 0x1001, E.REG_WD_SM, struct.pack("<H", 5))             # 0.5 ms < 1 ms
    request_state(app, esm.SAFEOP | esm.ACK)
    assert app.stack.esc.al_code == 0x001F
    one(app, E.FPWR, 0x1001, E.REG_WD_SM, struct.pack("<H", 1000))
    assert request_state(app, esm.SAFEOP | esm.ACK) == esm.SAFEOP


def test_sm_watchdog_in_op_goes_to_safeop_with_001b_and_outputs_safe(app):
    configure_mailbox(app)
    request_state(app, esm.PREOP)
    for n, (start, ctl) in enumerate(((0x1100, 0x64), (0x1180, 0x20))):
        one(app, E.FPWR, 0x1001, E.REG_SM + 8 * (n + 2),
            struct.pack("<HHBBBB", start, 24, ctl, 0, 1, 0))
    esc = app.stack.esc
    request_state(app, esm.SAFEOP)
    assert request_state(app, esm.OP) == esm.OP and app.operational
    esc.process(frame((E.FPWR, 0x1001, 0x1100, bytes(24))), now=1_000_000)
    esc.tick(1_000_000 + esc.watchdog_ns() - 1)
    assert app.stack.state == esm.OP
    esc.tick(1_000_000 + esc.watchdog_ns() + 1)
    assert esc.al_status == esm.SAFEOP | esm.ERROR_FLAG and esc.al_code == 0x001B
    assert not app.operational


# -- CoE (5.4) -----------------------------------------------------------------------
def sdo(server: CoeServer, cmd: int, index: int, sub: int, data: bytes = bytes(4)) -> bytes:
    answers = server.handle(struct.pack("<H", 0x2000) + struct.pack("<BHB", cmd, index, sub)
                            + data)
    assert len(answers) == 1
    return answers[0]


def segment(server: CoeServer, cmd: int, data: bytes) -> bytes:
    answers = server.handle(struct.pack("<H", 0x2000) + bytes([cmd]) + data)
    assert len(answers) == 1
    return answers[0]


def abort_code(answer: bytes) -> int:
    assert answer[1] >> 4 == 2 and answer[2] == 0x80, answer.hex()
    return struct.unpack_from("<I", answer, 6)[0]


@pytest.fixture
def server() -> CoeServer:
    return CoeServer(Dictionary(build_table("EB02")), ident.MBX_IN_SIZE)


def test_sdo_abort_codes_of_5_4_1(server):
    assert abort_code(sdo(server, 0x40, 0x2000, 0)) == 0x06020000
    assert abort_code(sdo(server, 0x40, 0x1018, 7)) == 0x06090011
    assert abort_code(sdo(server, 0x40, 0x1600, 0)) == 0x06020000          # N/A object
    assert abort_code(sdo(server, 0x23, 0x1018, 1, b"\1\0\0\0")) == 0x06010002
    assert abort_code(sdo(server, 0x2F, 0x1C12, 1, b"\1\0\0\0")) == 0x06070013
    assert abort_code(sdo(server, 0x23, 0x1C12, 1, b"\1\x16\0\0")) == 0x06070012
    assert abort_code(sdo(server, 0x2B, 0x1C12, 1, b"\1\x16\0\0")) == 0x06010003
    assert abort_code(sdo(server, 0x2B, 0x1C32, 1, b"\5\0\0\0")) == 0x06090031
    assert abort_code(sdo(server, 0xE0, 0x1000, 0)) == 0x05040001
    assert abort_code(sdo(server, 0x60, 0x1000, 0)) == 0x05040001          # no transfer


def test_sdo_expedited_download_and_upload(server):
    assert sdo(server, 0x23, 0x10F1, 2, b"\x09\0\0\0")[2] == 0x60
    answer = sdo(server, 0x40, 0x10F1, 2)
    assert answer[2] == 0x43 and struct.unpack_from("<I", answer, 6)[0] == 9


def test_sdo_segmented_upload_with_toggle_in_a_small_mailbox():
    server = CoeServer(Dictionary(build_table("EB02")), 24)
    first = sdo(server, 0x40, 0x1008, 0)
    assert first[2] == 0x41 and struct.unpack_from("<I", first, 6)[0] == 36
    text = first[10:]
    toggle = 0
    while True:
        seg = segment(server, 0x60 | toggle, bytes(7))
        flags = seg[2]
        assert flags & 0x10 == toggle
        size = 7 - ((flags >> 1) & 7) if len(seg) == 10 else len(seg) - 3
        text += seg[3:3 + size]
        toggle ^= 0x10
        if flags & 1:
            break
    assert text.rstrip(b"\0") == b"EB02 CM2 EtherCAT Cool MUSCLE Bridge"
    assert abort_code(segment(server, 0x60, bytes(7))) == 0x05040001


def test_sdo_segmented_download_and_toggle_error():
    server = CoeServer(Dictionary(build_table("EB02")), 24)
    text = b"K53.1=10 ?96.1 ?99.1 ^.1 K37.1=1"
    room = 24 - 6 - 2 - 8
    assert sdo(server, 0x21, 0xF581, 0, struct.pack("<I", len(text)) + text[:room])[2] == 0x60
    rest, toggle = text[room:], 0
    while rest:
        chunk, rest = rest[:14], rest[14:]
        pad = (7 - len(chunk)) << 1 if len(chunk) < 7 else 0
        answer = segment(server, toggle | pad | (0 if rest else 1), chunk.ljust(7, b"\0"))
        assert answer[2] == 0x20 | toggle
        toggle ^= 0x10
    assert server.od.get(0xF581, 0) == text.decode()
    sdo(server, 0x21, 0xF581, 0, struct.pack("<I", 40) + b"x" * room)
    assert abort_code(segment(server, 0x10, b"y" * 7)) == 0x05030000


def test_sdo_complete_access_pads_subindex_0_to_16_bits(server):
    answer = sdo(server, 0x50, 0x1018, 0)
    size, = struct.unpack_from("<I", answer, 6)
    assert answer[2] == 0x51 and size == 2 + 16
    assert answer[10:12] == b"\x04\x00"
    assert struct.unpack_from("<IIII", answer, 12) == (ident.VENDOR_ID, 0x00EB0002,
                                                        ident.REVISION, ident.SERIAL)
    assert struct.unpack_from("<4H", sdo(server, 0x50, 0x1C12, 0), 12) == \
        (0x1601, 0x1611, 0x1621, 0x1631)


def test_sdo_information_lists_and_describes_the_dictionary(server):
    def info(opcode: int, body: bytes) -> list[bytes]:
        return server.handle(struct.pack("<H", 0x8000) + struct.pack("<BBH", opcode, 0, 0) + body)
    counts = info(1, b"\0\0")[0]
    total, rx, tx = struct.unpack_from("<HHH", counts, 8)
    assert total == len(server.od.objects()) and rx == 8 and tx == 8   # 6040h/607Ah x 4
    pieces = info(1, b"\1\0")
    assert len(pieces) > 1 and pieces[0][2] & 0x80 and not pieces[-1][2] & 0x80
    listed = b"".join(p[6:] for p in pieces)[2:]
    indexes = struct.unpack(f"<{len(listed) // 2}H", listed)
    assert indexes[:3] == (0x1000, 0x1001, 0x1008) and 0x6040 in indexes and 0x1600 not in indexes
    desc = info(3, b"\x18\x10")[0]
    assert struct.unpack_from("<HHBB", desc, 6) == (0x1018, 0x002A, 4, 9)
    assert desc[12:] == b"Identity"
    entry = info(5, b"\x18\x10\x01\x00")[0]
    assert struct.unpack_from("<HBBHHH", entry, 6) == (0x1018, 1, 0, 0x0007, 32, 0x0007)
    assert entry[16:] == b"Vendor ID"
    err = info(5, b"\x18\x10\x09\x00")[0]
    assert err[2] == 7 and struct.unpack_from("<I", err, 6)[0] == 0x06090011


def test_fmmu2_maps_the_mailbox_full_bit_bitwise_2_3(app):
    """FMMU2 (manual 2.3: mailbox status): one bit, SM1 status 0x080D bit 3, to logical bit 5."""
    configure_mailbox(app)
    request_state(app, esm.PREOP)
    one(app, E.FPWR, 0x1001, E.REG_FMMU + 32,
        struct.pack("<IHBBHBBB3x", 0x20000, 1, 5, 5, E.REG_SM + 13, 3, 1, 1))
    assert one(app, E.LRD, 0x0000, 0x0002, b"\x00\x00")[1:] == (b"\x00\x00", 1)
    sdo = struct.pack("<HHBB", 10, 0, 0, 0x13) + struct.pack("<H", 0x2000) + \
        struct.pack("<BHBI", 0x40, 0x1000, 0, 0)
    one(app, E.FPWR, 0x1001, ident.MBX_OUT_START, sdo.ljust(128, b"\0"))
    _a, data, wkc = one(app, E.LRD, 0x0000, 0x0002, b"\x00\x00")
    assert (data, wkc) == (b"\x20\x00", 1)                 # only logical bit 5, nothing more
    _a, data, _w = one(app, E.LRD, 0x0000, 0x0002, b"\xdf\xff")
    assert data == b"\xff\xff"                              # the other bits pass untouched


def test_a_master_that_never_reads_answers_finds_the_receive_mailbox_full(app):
    configure_mailbox(app)
    request_state(app, esm.PREOP)
    sdo = struct.pack("<HHBB", 10, 0, 0, 0x13) + struct.pack("<H", 0x2000) + \
        struct.pack("<BHBI", 0x40, 0x1000, 0, 0)
    wkcs = [one(app, E.FPWR, 0x1001, ident.MBX_OUT_START, sdo.ljust(128, b"\0"))[2]
            for _ in range(60)]
    assert wkcs.count(1) < 60 and wkcs[-1] == 0           # bounded: SM0 stays full
    answers = 0
    while one(app, E.FPRD, 0x1001, ident.MBX_IN_START, bytes(128))[2]:
        answers += 1
    assert answers == wkcs.count(1)                        # every request taken is answered
    assert one(app, E.FPWR, 0x1001, ident.MBX_OUT_START, sdo.ljust(128, b"\0"))[2] == 1


def test_a_download_announcing_gigabytes_is_refused_out_of_memory(server):
    assert abort_code(sdo(server, 0x21, 0xF581, 0, struct.pack("<I", 1 << 30))) == 0x05040005


def test_an_unavailable_mode_of_operation_is_set_to_csp_6_2_2_note_3():
    app = BridgeApp(None)
    server = app.stack.coe
    assert sdo(server, 0x2F, 0x6860, 0, b"\x03\0\0\0")[2] == 0x60     # pv (3): N/A
    assert app.dictionary.get(0x6860, 0) == 8
    assert sdo(server, 0x2F, 0x6860, 0, b"\x06\0\0\0")[2] == 0x60     # hm
    assert app.dictionary.get(0x6860, 0) == 6


# -- SyncManagers a master points at the registers (ESC datasheet II 0x0800, 5.2.2) -----
SDO_1018 = (struct.pack("<HHBB", 10, 0, 0, 0x13) + struct.pack("<H", 0x2000)
            + struct.pack("<BHBI", 0x40, 0x1018, 1, 0)).ljust(128, b"\0")


def sm_regs(app: BridgeApp, n: int) -> tuple[int, int, int, int]:
    """(start, length, control, activate) as the master reads them back."""
    data = one(app, E.FPRD, 0x1001, E.REG_SM + 8 * n, bytes(8))[1]
    start, length, control, _status, activate = struct.unpack_from("<HHBBB", data)
    return start, length, control, activate


def to_op(app: BridgeApp) -> None:
    """What SOEM does: INIT with acknowledge, SyncManagers cleared, configured, up to OP."""
    request_state(app, esm.INIT | esm.ACK)
    one(app, E.FPWR, 0x1001, E.REG_SM, bytes(32))
    configure_mailbox(app)
    for n, (start, ctl) in enumerate(((0x1100, 0x64), (0x1180, 0x20))):
        one(app, E.FPWR, 0x1001, E.REG_SM + 8 * (n + 2),
            struct.pack("<HHBBBB", start, 24, ctl, 0, 1, 0))
    for state in (esm.PREOP, esm.SAFEOP, esm.OP):
        assert request_state(app, state) == state, hex(app.stack.esc.al_code)


def test_an_activated_syncmanager_keeps_its_settings(app):
    """Start, length and control are written only while the SyncManager is deactivated."""
    configure_mailbox(app)
    assert request_state(app, esm.PREOP) == esm.PREOP
    one(app, E.FPWR, 0x1001, E.REG_SM + 8, struct.pack("<HHBBBB", 0x0130, 128, 0x22, 0, 1, 0))
    assert sm_regs(app, 1) == (ident.MBX_IN_START, 128, 0x22, 1)
    assert one(app, E.FPWR, 0x1001, ident.MBX_OUT_START, SDO_1018)[2] == 1
    _a, answer, wkc = one(app, E.FPRD, 0x1001, ident.MBX_IN_START, bytes(128))
    assert wkc == 1 and struct.unpack_from("<I", answer, 12)[0] == ident.VENDOR_ID
    assert app.stack.esc.al_status == esm.PREOP


def test_a_read_mailbox_pointed_at_the_registers_never_writes_them_0016_5_2_2(app):
    """The attack: SM1 deactivated, pointed at AL status (0x0130), activated, then an SDO
    request.  The ESC does not activate a SyncManager outside the process RAM; the slave,
    whose mailbox configuration changed in PRE-OP, goes to INIT with 0016h; nothing is
    written over the registers; a master that configures it again reaches OP."""
    configure_mailbox(app)
    assert request_state(app, esm.PREOP) == esm.PREOP
    registers = bytes(app.stack.esc.mem[0x0130:0x01B0])
    one(app, E.FPWR, 0x1001, E.REG_SM + 8 + 6, b"\x00")                  # SM1 deactivated
    assert app.stack.esc.al_status == esm.INIT | esm.ERROR_FLAG
    assert app.stack.esc.al_code == 0x0016
    one(app, E.FPWR, 0x1001, E.REG_SM + 8, struct.pack("<HHBBBB", 0x0130, 128, 0x22, 0, 1, 0))
    assert sm_regs(app, 1) == (0x0130, 128, 0x22, 0)                     # not activated
    one(app, E.FPWR, 0x1001, ident.MBX_OUT_START, SDO_1018)
    assert request_state(app, esm.PREOP) == esm.INIT | esm.ERROR_FLAG    # not acknowledged
    assert bytes(app.stack.esc.mem[0x0130:0x01B0])[:4] == bytes((0x11, 0, 0, 0))
    assert bytes(app.stack.esc.mem[0x0138:0x01B0]) == registers[8:]
    assert request_state(app, esm.PREOP | esm.ACK) == esm.INIT | esm.ERROR_FLAG
    assert app.stack.esc.al_code == 0x0016                               # still pointed there
    to_op(app)
    assert app.stack.esc.al_status == esm.OP and app.stack.esc.al_code == 0


@pytest.mark.parametrize("n, start, code", [(1, 0x0FF0, 0x0016), (0, 0x2FC0, 0x0016)])
def test_a_syncmanager_reaching_outside_the_process_ram_is_not_activated(app, n, start, code):
    configure_mailbox(app)
    request_state(app, esm.PREOP)
    one(app, E.FPWR, 0x1001, E.REG_SM + 8 * n + 6, b"\x00")
    one(app, E.FPWR, 0x1001, E.REG_SM + 8 * n, struct.pack("<HHBBBB", start, 128,
                                                            0x22 | 4 * (n == 0), 0, 1, 0))
    assert sm_regs(app, n)[3] == 0
    assert len(app.stack.esc.mem) == E.MEM_SIZE
    assert (app.stack.esc.al_status, app.stack.esc.al_code) == (esm.INIT | esm.ERROR_FLAG, code)


@pytest.mark.parametrize("n, code", [(2, 0x001D), (3, 0x001E)])
def test_a_process_data_syncmanager_deactivated_in_op_goes_to_preop(app, n, code):
    to_op(app)
    one(app, E.FPWR, 0x1001, E.REG_SM + 8 * n + 6, b"\x00")
    assert (app.stack.esc.al_status, app.stack.esc.al_code) == (esm.PREOP | esm.ERROR_FLAG, code)
    assert (esm.OP, esm.PREOP, code) in app.stack.transitions
    to_op(app)


def test_syncmanagers_cleared_in_init_change_nothing(app):
    configure_mailbox(app)
    one(app, E.FPWR, 0x1001, E.REG_SM, bytes(32))
    assert (app.stack.esc.al_status, app.stack.esc.al_code) == (esm.INIT, 0)


@settings(max_examples=400, deadline=None)
@given(status=st.integers(0, 0xFFFF), code=st.integers(0, 0xFFFF),
       control=st.integers(0, 0xFFFF), refuse=st.sampled_from([0, 0x0016, 0x001D]))
def test_the_state_machine_is_total(status, code, control, refuse):
    """No AL status and no AL control value makes it raise; the outcome names a state."""
    for out in (esm.request(status, code, control, lambda a, b: refuse),
                esm.fault(status, esm.SAFEOP, esm.SM_WATCHDOG),
                esm.fault(status, esm.INIT, esm.INVALID_MAILBOX_CONFIG)):
        assert out.state in (esm.INIT, esm.PREOP, esm.SAFEOP, esm.OP)
        assert out.al_status & ~0x1F == 0


def test_an_al_status_naming_no_state_counts_as_init():
    out = esm.request(0x000A, 0x1300, esm.INIT | esm.ACK, lambda a, b: 0)
    assert (out.al_status, out.code, out.changed) == (esm.INIT, 0, True)
    out = esm.request(0x000A, 0x1300, 0x0007, lambda a, b: 0)
    assert (out.state, out.error, out.code) == (esm.INIT, True, 0x0012)


# -- bit-wise FMMUs (ETG.1000.4; ESC datasheet II 0x0600) -----------------------------------
def _reference_lrd(mem: bytes, addr: int, length: int, fm: tuple[int, ...],
                   before: bytes) -> bytes:
    """Bit by bit: what a read FMMU puts into an LRD at ``addr`` (LSB first)."""
    lstart, llen, lsb, leb, pstart, psb = fm
    out = bytearray(before)
    for k in range((llen - 1) * 8 + leb - lsb + 1):
        lbit = (lstart - addr) * 8 + lsb + k
        pbit = pstart * 8 + psb + k
        if 0 <= lbit < length * 8:
            value = mem[pbit // 8] >> (pbit % 8) & 1 if pbit // 8 < len(mem) else 0
            out[lbit // 8] = out[lbit // 8] & ~(1 << lbit % 8) | value << lbit % 8
    return bytes(out)


def _reference_lwr(mem: bytes, addr: int, data: bytes, fm: tuple[int, ...]) -> bytes:
    lstart, llen, lsb, leb, pstart, psb = fm
    out = bytearray(mem)
    for k in range((llen - 1) * 8 + leb - lsb + 1):
        lbit = (lstart - addr) * 8 + lsb + k
        pbit = pstart * 8 + psb + k
        if 0 <= lbit < len(data) * 8:
            value = data[lbit // 8] >> (lbit % 8) & 1
            out[pbit // 8] = out[pbit // 8] & ~(1 << pbit % 8) | value << pbit % 8
    return bytes(out)


def _bitwise_app(fm: tuple[int, ...], kind: int) -> BridgeApp:
    a = BridgeApp(None)
    lstart, llen, lsb, leb, pstart, psb = fm
    one(a, E.APWR, 0, E.REG_FMMU, struct.pack("<IHBBHBBB3x", lstart, llen, lsb, leb, pstart,
                                               psb, kind, 1))
    return a


@settings(max_examples=150, deadline=None)
@given(lstart=st.integers(0x10000, 0x10010), llen=st.integers(1, 12),
       lsb=st.integers(0, 7), leb=st.integers(0, 7), pstart=st.integers(0x1400, 0x1410),
       psb=st.integers(0, 7), addr=st.integers(0x0FFF8, 0x10020), length=st.integers(1, 24),
       seed=st.integers(0, 1 << 16))
def test_bitwise_fmmu_matches_the_bit_by_bit_mapping(lstart, llen, lsb, leb, pstart, psb,
                                                     addr, length, seed):
    import random
    rng = random.Random(seed)
    fm = (lstart, llen, lsb, leb, pstart, psb)
    a = _bitwise_app(fm, 1)
    a.stack.esc.mem[0x1400:0x1420] = rng.randbytes(32)
    before = rng.randbytes(length)
    _x, data, _w = one(a, E.LRD, addr & 0xFFFF, addr >> 16, before)
    assert data == _reference_lrd(bytes(a.stack.esc.mem), addr, length, fm, before)
    b = _bitwise_app(fm, 2)
    b.stack.esc.mem[0x1400:0x1420] = rng.randbytes(32)
    old = bytes(b.stack.esc.mem)
    incoming = rng.randbytes(length)
    one(b, E.LWR, addr & 0xFFFF, addr >> 16, incoming)
    assert bytes(b.stack.esc.mem) == _reference_lwr(old, addr, incoming, fm)


def _lines_run(fn) -> int:
    """Python lines executed in the engine's modules while ``fn`` runs (the work, counted)."""
    import sys
    from pathlib import Path

    engine = str(Path(E.__file__).parent)
    count = 0

    def local(frame, event, arg):
        nonlocal count
        if event == "line":
            count += 1
        return local

    def calls(frame, event, arg):
        return local if frame.f_code.co_filename.startswith(engine) else None
    old = sys.gettrace()
    sys.settrace(calls)
    try:
        fn()
    finally:
        sys.settrace(old)
    return count


def test_a_bitwise_fmmu_costs_what_it_overlaps_not_what_it_spans():
    """An LRD of 4 bytes into a bit-wise FMMU of 65,535 bytes does the work of one into a
    bit-wise FMMU of 8 bytes (it was a loop over every bit of the FMMU, 524,273 of them)."""
    def lrd(llen: int) -> int:
        a = _bitwise_app((0x10000, llen, 3, 7, 0x1000, 5), 1)
        request = frame((E.LRD, 0x0002, 0x0001, bytes(4)))
        return _lines_run(lambda: a.stack.esc.process(request))
    small, large = lrd(8), lrd(65535)
    assert large <= small + 5, (small, large)
    assert small < 200
