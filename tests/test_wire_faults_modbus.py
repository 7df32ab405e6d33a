"""Modbus wire faults (docs/wire-faults.md): the exact frames in virtual time, then what
independent masters see: pymodbus (retries counted on the response, exceptions
decoded) and Debian's mbpoll (libmodbus's own error texts), over a socat pty pair
(RTU, 5.6.1) and over Modbus TCP.

Frames are 5.6.3's: address, PDU, CRC-16 low byte first (the CRC computed bit by bit
in modbus_support, independently of the model's table).
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ModbusIOException

from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.transports.modbus_tcp import ModbusTcpTransport
from coolmuscle.frontends.transports.serial_line import ModbusRtuTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.sim.kernel import ms
from modbus_support import Wire, crc, frame, needs_mbpoll, needs_socat, socat_pty_pair

READ_P0 = frame("01 03 00 C8 00 02")               # FC03, P0 (K78=0: register 200)
P0_IS_0 = frame("01 03 04 00 00 00 00")


def wire_events(w: Wire) -> list[str]:
    return [e.text for e in w.events if e.kind == "wire"]


@pytest.fixture
def rtu() -> Wire:
    return Wire(K81_1=1)


def test_rtu_reply_without_fault(rtu):
    assert rtu.transact(READ_P0) == P0_IS_0


def test_bad_crc_inverts_the_crc_bytes(rtu):
    rtu.chain.inject_wire_fault("modbus-rtu", "bad_crc", count=1)
    got = rtu.transact(READ_P0)
    assert got[:-2] == P0_IS_0[:-2] and got[-2:] == bytes(b ^ 0xFF for b in P0_IS_0[-2:])
    assert crc(got[:-2]) != got[-2:]
    assert rtu.transact(READ_P0) == P0_IS_0                     # count = 1: once
    assert wire_events(rtu) == ["wire fault 1 modbus-rtu bad_crc: reply 01 03 04 00 00 00 "
                                "00 fa 33: CRC fa 33 -> 05 cc"]


def test_wrong_slave_is_a_good_frame_from_another_address(rtu):
    rtu.chain.inject_wire_fault("modbus-rtu", "wrong_slave", address=7, count=1)
    assert rtu.transact(READ_P0) == frame("07 03 04 00 00 00 00")


def test_exception_refuses_the_request_without_serving_it(rtu):
    rtu.chain.inject_wire_fault("modbus-rtu", "exception", code=6, count=1)
    write_p0 = frame("01 10 00 C8 00 02 04 00 00 00 2A")
    assert rtu.transact(write_p0) == frame("01 90 06")
    assert rtu.chain.get_register(1, "P", 0) == 0
    assert rtu.transact(write_p0) == frame("01 10 00 C8 00 02")
    assert rtu.chain.get_register(1, "P", 0) == 42


def test_no_reply_leaves_the_request_unserved(rtu):
    rtu.chain.inject_wire_fault("modbus-rtu", "no_reply", count=1)
    assert rtu.transact(frame("01 10 00 C8 00 02 04 00 00 00 2A")) == b""
    assert rtu.chain.get_register(1, "P", 0) == 0


def test_broadcasts_and_other_stations_are_no_messages(rtu):
    rtu.chain.inject_wire_fault("modbus-rtu", "no_reply", count=1)
    rtu.transact(frame("02 03 00 C8 00 02"))                  # not this station
    rtu.transact(frame("00 10 00 C8 00 02 04 00 00 00 05"))   # broadcast: executed, silent
    assert rtu.chain.get_register(1, "P", 0) == 5
    assert rtu.transact(READ_P0) == b""                      # the first message


def test_late_reply_and_the_next_one_wait_in_order(rtu):
    rtu.chain.inject_wire_fault("modbus-rtu", "late", ms=100, count=1)
    times: list[tuple[int, bytes]] = []
    rtu.chain.host_line.add_listener(lambda d: times.append((rtu.kernel.now, d)))
    rtu.send(READ_P0)
    rtu.idle(ms(20))
    rtu.send(READ_P0)
    rtu.idle(ms(200))
    gap = 64 * 10**9 // 38400                                    # 5.6.2 at K20=0
    assert [d for _t, d in times] == [P0_IS_0, P0_IS_0]
    assert times[0][0] == gap + ms(100)
    assert times[1][0] == times[0][0]                            # held behind the late one


def test_silence_gap_pauses_inside_the_frame(rtu):
    rtu.chain.inject_wire_fault("modbus-rtu", "silence", chars=4, count=1)
    times: list[tuple[int, bytes]] = []
    rtu.chain.host_line.add_listener(lambda d: times.append((rtu.kernel.now, d)))
    rtu.send(READ_P0)
    rtu.idle(ms(50))
    char = 10 * 10**9 // 38400                                   # 10 bits a byte (5.6.1)
    assert [d for _t, d in times] == [P0_IS_0[:4], P0_IS_0[4:]]
    assert times[1][0] - times[0][0] == 4 * char


def test_silence_merge_runs_two_frames_together(rtu):
    rtu.chain.inject_wire_fault("modbus-rtu", "silence", mode="merge", count=1)
    assert rtu.transact(READ_P0) == P0_IS_0 * 2


def test_a_motor_powered_off_gets_no_modbus_request():
    w = Wire(motors=2, K81_1=1, K84_2=-4)
    read_id2 = frame("04 03 00 C8 00 02")
    assert w.transact(read_id2) == frame("04 03 04 00 00 00 00")
    w.chain.inject_wire_fault("chain", "power_off", motor=2, until=0.5)
    assert w.transact(read_id2) == b""
    assert w.transact(READ_P0) == P0_IS_0                      # ID1 still answers
    w.idle(ms(600))
    assert w.transact(read_id2) == frame("04 03 04 00 00 00 00")


def test_modbus_tcp_door_exception_and_no_reply_in_the_model():
    chain = Chain()
    chain.inject_wire_fault("modbus-tcp", "exception", code=3, count=1)
    assert chain.modbus_request(1, bytes.fromhex("03 00 C8 00 02"), tcp=True) == b"\x83\x03"
    chain.inject_wire_fault("modbus-tcp", "no_reply", count=1)
    assert chain.modbus_request(1, bytes.fromhex("03 00 C8 00 02"), tcp=True) is None
    assert chain.modbus_request(1, bytes.fromhex("03 00 C8 00 02"), tcp=True) == \
        bytes.fromhex("03 04 00 00 00 00")


# -- real masters ----------------------------------------------------------------------------


@pytest.fixture
def sim(tmp_path: Path) -> Iterator[tuple[ServiceThread, str, int]]:
    with socat_pty_pair(tmp_path) as (ours, theirs):
        st = ServiceThread(lambda: Chain(motors=1), lambda: [
            ModbusRtuTransport(where=ours), ModbusTcpTransport(port=0)]).start()
        try:
            yield st, theirs, st.transports[1].info()["port"]
        finally:
            st.stop()


def inject(st: ServiceThread, door: str, kind: str, **params: object) -> None:
    st.call(lambda: st.chain.inject_wire_fault(door, kind, count=1, **params))


@needs_socat
@pytest.mark.peer
@pytest.mark.parametrize("kind, params", [("bad_crc", {}), ("no_reply", {}),
                                          ("wrong_slave", {}), ("late", {"ms": 700})])
def test_pymodbus_rtu_retries_and_counts_the_retry(sim, kind, params):
    """The late reply (0.7 s) comes while the retry (sent at 0.5 s) waits: RTU has no
    transaction id, so it answers the retry; the retry's own reply then waits behind it
    and is thrown away before the next request."""
    st, path, _ = sim
    client = ModbusSerialClient(path, baudrate=38400, timeout=0.5, retries=1)
    assert client.connect()
    try:
        inject(st, "modbus-rtu", kind, **params)
        reply = client.read_holding_registers(200, count=2, device_id=1)
        assert not reply.isError() and reply.registers == [0, 0]
        assert reply.retries == 1                   # the first try failed: counted
        time.sleep(0.3)                              # what came late has passed
        reply = client.read_holding_registers(200, count=2, device_id=1)
        assert reply.retries == 0                    # the next request: straight through
    finally:
        client.close()


@needs_socat
@pytest.mark.peer
def test_pymodbus_rtu_without_retries_gives_up_and_decodes_exceptions(sim):
    st, path, _ = sim
    client = ModbusSerialClient(path, baudrate=38400, timeout=0.5, retries=0)
    assert client.connect()
    try:
        inject(st, "modbus-rtu", "bad_crc")             # the frame is thrown away: no reply
        with pytest.raises(ModbusIOException, match="No response received after 0 retries"):
            client.read_holding_registers(200, count=2, device_id=1)
        inject(st, "modbus-rtu", "exception", code=4)
        reply = client.read_holding_registers(200, count=2, device_id=1)
        assert reply.isError() and reply.exception_code == 4
        assert client.read_holding_registers(200, count=2, device_id=1).registers == [0, 0]
    finally:
        client.close()


def mbpoll(*where: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["mbpoll", "-a", "1", "-o", "0.5", "-t", "4:hex", "-r", "201",
                           "-c", "2", "-1", *where], capture_output=True, text=True,
                          timeout=20)


@needs_socat
@needs_mbpoll
@pytest.mark.peer
def test_mbpoll_rtu_says_what_libmodbus_saw(sim):
    st, path, _ = sim
    where = ("-m", "rtu", "-b", "38400", "-P", "none", path)
    for kind, params, says in [
            ("bad_crc", {}, "Invalid CRC"),
            ("no_reply", {}, "Connection timed out"),
            ("wrong_slave", {}, "Response not from requested slave"),
            ("exception", {"code": 4}, "Slave device or server failure")]:
        inject(st, "modbus-rtu", kind, **params)
        out = mbpoll(*where)
        assert out.returncode == 1 and says in out.stderr, (kind, out.stderr)
        ok = mbpoll(*where)
        assert ok.returncode == 0 and "[201]: \t0x0000" in ok.stdout, (kind, ok.stderr)
    # a pause of 3000 characters (0.78 s) inside the frame: libmodbus's byte timeout
    # (0.5 s) ends the read; the frame's tail stays in the pty for whoever reads next
    inject(st, "modbus-rtu", "silence", chars=3000)
    out = mbpoll(*where)
    assert out.returncode == 1 and "Connection timed out" in out.stderr, out.stderr


@needs_mbpoll
@pytest.mark.peer
def test_mbpoll_and_pymodbus_over_tcp(sim):
    st, _, port = sim
    where = ("-m", "tcp", "-p", str(port), "127.0.0.1")
    for kind, params, says in [("no_reply", {}, "Connection timed out"),
                               ("exception", {"code": 6}, "Slave device or server is busy"),
                               ("late", {"ms": 1500}, "Connection timed out")]:
        inject(st, "modbus-tcp", kind, **params)
        out = mbpoll(*where)
        assert out.returncode == 1 and says in out.stderr, (kind, out.stderr)
    inject(st, "modbus-tcp", "wrong_unit")
    assert mbpoll(*where).returncode == 0          # libmodbus does not check the unit id
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=0.5, retries=1)
    assert client.connect()
    try:
        inject(st, "modbus-tcp", "wrong_unit")    # pymodbus does: it skips it and retries
        reply = client.read_holding_registers(200, count=2, device_id=1)
        assert reply.registers == [0, 0] and reply.retries == 1
        inject(st, "modbus-tcp", "exception", code=2)
        reply = client.read_holding_registers(200, count=2, device_id=1)
        assert reply.isError() and reply.exception_code == 2
    finally:
        client.close()
