"""COM0 as a Modbus RTU slave: the example frames of cml-users-guide.txt 5.6.2–5.6.9, exactly.

Frames are written as the manual's tables give them; the CRC is appended by the
independent bit-by-bit CRC of tests/modbus_support.py.  The chain runs in virtual
time: bytes go in through the host line, the 5.6.2 silent interval ends each frame.
"""

from __future__ import annotations

import ast
import random
from pathlib import Path

import pytest

import coolmuscle.chain.firmware_modbus
from coolmuscle.chain.daisy import Chain
from coolmuscle.chain.firmware_modbus.rtu import silent_interval_ns
from coolmuscle.sim.kernel import ms, seconds
from modbus_support import Wire, crc, frame, gap_ns

#: 5.6.7 "In case of using the following parameter settings": K78=100, K79=200, K80=300, K81=1.
MANUAL = {"K78_1": 100, "K79_1": 200, "K80_1": 300, "K81_1": 1}


def test_crc_anchor_and_model_crc_agree_with_pymodbus() -> None:
    from pymodbus.framer.rtu import FramerRTU

    from coolmuscle.chain.firmware_modbus import crc16
    assert crc(bytes.fromhex("010300000001")) == bytes.fromhex("840A")
    rng = random.Random(16)
    for body in [b"", b"\x01", bytes(range(256)), b"\xff" * 7] + \
            [rng.randbytes(rng.randint(1, 300)) for _ in range(200)]:
        assert crc16(body) == crc(body) == FramerRTU.compute_CRC(body).to_bytes(2, "big")


def test_the_modbus_model_imports_no_clock_sockets_threads_or_pymodbus() -> None:
    """docs/architecture.md rule 1: the pure Modbus logic does no I/O and reads no clock."""
    package = Path(coolmuscle.chain.firmware_modbus.__file__).parent
    for path in package.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                assert name.split(".")[0] not in {"time", "asyncio", "socket", "threading",
                                                  "pymodbus", "serial", "select"}, (path, name)


# -- 5.6.7 Function Code 03 ---------------------------------------------------------
def test_5_6_7_fc03_read_p0() -> None:
    wire = Wire(**MANUAL)
    wire.chain.set_register(1, "P", 0, 12345)
    request = frame("01 03 01 2C 00 02")           # start 300 = K78+200, 2 registers
    assert wire.transact(request) == frame("01 03 04 00 00 30 39")


def test_5_6_7_fc03_live_values_and_the_whole_table() -> None:
    wire = Wire(K81_1=1)
    chain = wire.chain
    chain.execute("S.1=100, A.1=100, P.1=2000, ^.1, V3.1=-7, K42.1=25, T8.1=900, H0.1=12")
    chain.execute('V4.1="Px"')
    wire.idle(seconds(1))
    snap = chain.snapshot(1)
    assert snap.position == 2000 and snap.status == 8

    def read(offset: int, count: int = 2) -> list[int]:
        reply = wire.transact(frame(f"01 03 {offset:04X} {count:04X}"))
        assert reply[:3] == bytes((1, 3, 2 * count)) and reply[-2:] == crc(reply[:-2])
        data = reply[3:-2]
        return [int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2)]

    def long(offset: int) -> int:
        high, low = read(offset)
        value = high << 16 | low
        return value - (1 << 32) if value >= 1 << 31 else value

    assert long(2) == 2000 and long(8) == 8                      # ?96, ?99
    assert long(10 + 2 * 3) == -7 and long(10 + 2 * 4) == 2000   # V3, V4 bound to Px
    assert long(200 + 2 * 0) == 2000 and long(602) == 100        # P0, S0
    assert long(634) == 100 and long(652) == 100                 # A0, M0
    assert long(670) == 12 and long(686) == snap.temperature     # H0, ?71
    assert long(696 + 2 * 7) == 900                              # T8
    assert long(752 + 2 * (42 - 20)) == 25                       # K42
    assert long(752 + 2 * (81 - 20)) == 1                        # K81
    assert read(0, 10)[2:4] == [0, 2000]                         # one read over five values
    assert read(3, 1) == [2000]                                  # the low word alone


@pytest.mark.parametrize("offset", [42, 50, 60, 99, 100, 102, 104, 199, 672, 684, 688, 694,
                                    712, 750, 892, 1000])
def test_5_6_8_fc03_gaps_of_the_table_are_exception_02(offset: int) -> None:
    wire = Wire(K81_1=1)
    assert wire.transact(frame(f"01 03 {offset:04X} 00 02")) == frame("01 83 02")


def test_5_6_8_fc03_below_k78_and_huge_counts_are_exception_02() -> None:
    wire = Wire(**MANUAL)
    assert wire.transact(frame("01 03 00 62 00 02")) == frame("01 83 02")   # K78-2
    assert wire.transact(frame("01 03 01 2C 00 00")) == frame("01 83 02")   # count 0
    assert wire.transact(frame("01 03 01 2C 00 7E")) == frame("01 83 02")   # 126 > 125
    assert wire.transact(frame("01 03 01 2C FF FF")) == frame("01 83 02")
    assert wire.transact(frame("01 03 01 2C 00 7D"))[:3] == bytes.fromhex("01 03 FA")


# -- 5.6.5 Endian --------------------------------------------------------------------
@pytest.mark.parametrize("k85, data", [(0, "00 64 00 00"), (1, "00 00 00 64"),
                                       (2, "00 64 00 00"), (3, "00 00 00 64")])
def test_5_6_5_endian_of_6553600(k85: int, data: str) -> None:
    wire = Wire(K81_1=1, K85_1=k85)
    wire.chain.set_register(1, "P", 0, 6553600)
    assert wire.transact(frame("01 03 00 C8 00 02")) == frame(f"01 03 04 {data}")
    wire.transact(frame(f"01 10 00 CA 00 02 04 {data}"))                      # P1 the same way
    assert wire.chain.get_register(1, "P", 1) == 6553600


# -- 5.6.7 Function Code 04 ------------------------------------------------------------
def test_5_6_7_fc04_inputs_of_id3_to_id5() -> None:
    wire = Wire(motors=5, **MANUAL)
    for motor, inputs in ((3, (1, 2, 3, 4, 5, 6)), (4, (2,)), (5, (1, 3, 5))):
        for n in inputs:
            wire.chain.set_input(motor, n, True)
    request = frame("01 04 00 66 00 03")           # start 102 = K78+2: ID3
    # The manual's third word, 0x01FF, needs nine inputs; a CM2 has six (docs/fidelity.md).
    assert wire.transact(request) == frame("01 04 06 00 3F 00 02 00 15")


def test_5_6_7_fc04_outputs_status_and_absent_motors() -> None:
    wire = Wire(motors=2, K81_1=1, K34_1=3333)
    wire.chain.execute("O1.1, O3.1, ).2")
    reply = wire.transact(frame("01 04 00 10 00 03"))       # outputs of ID1..ID3
    assert reply == frame("01 04 06 00 05 00 00 00 00")
    reply = wire.transact(frame("01 04 00 20 00 02"))       # status of ID1, ID2
    assert reply == frame("01 04 04 00 08 00 10")
    assert wire.transact(frame("01 04 00 0E 00 02")) == frame("01 84 02")   # K78+15 gap
    assert wire.transact(frame("01 04 00 2F 00 01")) == frame("01 84 02")   # K78+47


# -- 5.6.7 Function Code 16 --------------------------------------------------------------
def test_5_6_7_fc16_method_by_writing_to_register_address() -> None:
    wire = Wire(**MANUAL)
    request = frame("01 10 01 2C 00 02 06 00 00 30 39 0D 00")
    assert wire.transact(request) == frame("01 10 01 2C 00 02")
    assert wire.chain.get_register(1, "P", 0) == 12345


def test_5_6_7_fc16_method_of_cml_command() -> None:
    """K78+100: ASCII up to '=', the value as a binary long, CR (the bytes say P1)."""
    wire = Wire(**MANUAL)
    request = frame("01 10 00 C8 00 02 06 50 31 3D 00 00 30 39 0D")
    assert wire.transact(request) == frame("01 10 00 C8 00 02")   # the manual's response
    assert wire.chain.get_register(1, "P", 1) == 12345


def test_5_6_7_fc16_method_of_cml_command_by_modbus() -> None:
    wire = Wire(**MANUAL)
    request = frame("01 10 00 CA 00 02 0A 50 31 3D 31 32 33 34 35 0D 00")
    assert wire.transact(request) == frame("01 10 00 CA 00 02")
    assert wire.chain.get_register(1, "P", 1) == 12345


def test_5_6_7_fc16_binary_value_follows_k85_and_standard_masters_send_no_cr() -> None:
    wire = Wire(**MANUAL, K85_1=1)
    wire.transact(frame("01 10 00 C8 00 04 08 50 32 3D 30 39 00 00 0D"))   # little endian
    assert wire.chain.get_register(1, "P", 2) == 12345
    wire.transact(frame("01 10 01 2C 00 04 08 FF FE FF FF 00 07 00 00"))     # P0, P1 no CR
    assert [wire.chain.get_register(1, "P", i) for i in (0, 1)] == [-2, 7]


def test_5_6_7_fc16_writes_every_row_of_its_table() -> None:
    wire = Wire(K81_1=1)
    rows = {"V15": 10 + 30, "P200": 600, "S15": 632, "A8": 650, "M8": 668, "H0": 670,
            "T1": 696, "T8": 710, "K89": 890, "K44": 752 + 48}
    values = {"V15": -5, "P200": 4321, "S15": -300, "A8": 77, "M8": 55, "H0": 9, "T1": 1,
              "T8": 8, "K89": 0, "K44": 250}
    for name, offset in rows.items():
        value = values[name] & 0xFFFFFFFF
        assert wire.transact(frame(f"01 10 {offset:04X} 00 02 04 {value:08X}")) == \
            frame(f"01 10 {offset:04X} 00 02")
    get = wire.chain.get_register
    assert wire.chain.register_value(1, "V", 15) == -5
    assert (get(1, "P", 200), get(1, "S", 15), get(1, "A", 8)) == (4321, -300, 77)
    assert (get(1, "M", 8), get(1, "H", 0), get(1, "T", 1), get(1, "T", 8)) == (55, 9, 1, 8)
    assert wire.chain.get_param(1, 44) == 250


def test_5_6_7_fc16_out_of_range_is_acknowledged_and_not_reflected() -> None:
    wire = Wire(K81_1=1, K23_1=17)
    reply = wire.transact(frame("01 10 03 20 00 02 04 00 00 01 F5"))   # K44=501 (1..500)
    assert reply == frame("01 10 03 20 00 02")
    assert wire.chain.get_param(1, 44) == 100
    assert [e.text for e in wire.events if e.kind == "message"] == ["error00.1: Out Of Range!!"]
    assert all(e.origin == "modbus" for e in wire.events)


@pytest.mark.parametrize("request_hex", [
    "01 10 00 00 00 02 04 00 00 00 01",    # Pe is read-only
    "01 10 00 38 00 02 04 00 00 00 01",    # ?70 inputs
    "01 10 02 AE 00 02 04 00 00 00 01",    # K78+686 temperature
    "01 10 00 C9 00 02 04 00 00 00 01",    # odd start (middle of P0)
    "01 10 00 C8 00 01 02 00 01",          # half a value
    "01 10 00 2A 00 02 04 00 00 00 01",    # K78+42, after V15
])
def test_5_6_8_fc16_not_writable_is_exception_02(request_hex: str) -> None:
    wire = Wire(K81_1=1)
    assert wire.transact(frame(request_hex)) == frame("01 90 02")


def test_5_6_8_a_memory_number_not_allocated_is_exception_02_to_read_and_to_write() -> None:
    """5.6.8 02 "The specified data address does not exist": P150 after ``\\P149``
    (2.1.2) reads and writes as 02; a write that covers it writes nothing at all."""
    wire = Wire(K81_1=1)
    wire.chain.execute("\\P149")
    assert wire.transact(frame("01 03 01 F4 00 02")) == frame("01 83 02")        # P150
    assert wire.transact(frame("01 10 01 F4 00 02 04 00 00 00 01")) == frame("01 90 02")
    assert wire.transact(frame("01 10 01 F2 00 04 08 00 00 00 07 00 00 00 01")) == \
        frame("01 90 02")                                                       # P149, P150
    assert wire.chain.get_register(1, "P", 149) == 0
    assert wire.transact(frame("01 10 01 F2 00 02 04 00 00 00 07")) == frame("01 10 01 F2 00 02")
    assert wire.chain.get_register(1, "P", 149) == 7


def test_5_6_8_fc16_data_that_does_not_fit_gets_no_reply() -> None:
    wire = Wire(K81_1=1)
    assert wire.transact(frame("01 10 00 C8 00 02 04 00 00 30")) == b""        # 3 of 4 bytes
    assert wire.transact(frame("01 10 00 C8 00 02 04 00 00 30 39 41")) == b""  # junk after
    assert wire.chain.get_register(1, "P", 0) == 0


# -- 5.6.8 Exception responses ------------------------------------------------------------
@pytest.mark.parametrize("function", [0x01, 0x02, 0x05, 0x06, 0x0F, 0x11, 0x2B, 0x7F])
def test_5_6_8_functions_of_the_slave_side_are_exception_01(function: int) -> None:
    wire = Wire(**MANUAL)
    assert wire.transact(frame(f"01 {function:02X} 01 2C 00 10")) == \
        frame(f"01 {function | 0x80:02X} 01")


def test_5_6_8_k78_minus_1_deactivates_the_host_functions() -> None:
    wire = Wire(K81_1=1, K78_1=-1)
    assert wire.transact(frame("01 03 00 C8 00 02")) == frame("01 83 01")
    assert wire.transact(frame("01 04 00 00 00 01")) == frame("01 84 01")
    assert wire.transact(frame("01 10 00 C8 00 02 04 00 00 00 01")) == frame("01 90 01")


# -- 5.6.3 / 5.6.4 / 5.6.6 addressing ---------------------------------------------------------
def test_5_6_3_other_addresses_and_bad_crc_get_no_reply() -> None:
    wire = Wire(K81_1=7)
    assert wire.transact(frame("01 03 00 C8 00 02")) == b""
    good = frame("07 03 00 C8 00 02")
    assert wire.transact(good[:-1] + bytes((good[-1] ^ 1,))) == b""
    assert wire.transact(good) == frame("07 03 04 00 00 00 00")
    assert wire.chain.modbus_line.bad_frames == 1


def test_5_6_4_broadcast_executes_without_response() -> None:
    wire = Wire(motors=3, K81_1=1, K84_2=-4)
    assert wire.transact(frame("00 10 00 C8 00 02 04 00 00 04 D2")) == b""   # P0=1234
    assert [wire.chain.get_register(m, "P", 0) for m in (1, 2, 3)] == [1234, 1234, 0]
    assert wire.transact(frame("00 03 00 C8 00 02")) == b""


def test_5_6_6_setting_example_2_device_disables_id2() -> None:
    """K84 < 0 gives ID2 Modbus address 4 and ID3 address 5; ``).2`` frees ID2."""
    wire = Wire(motors=3, K81_1=1, K84_2=-4, K84_3=-5)
    request = frame("04 10 00 64 00 02 04 29 2E 32 0D 0D")   # as printed: CR twice
    assert wire.transact(request) == frame("04 10 00 64 00 02")
    assert wire.chain.snapshot(2).status == 16 and wire.chain.snapshot(1).status == 8
    wire.chain.set_register(3, "P", 0, 55)
    assert wire.transact(frame("05 03 00 C8 00 02")) == frame("05 03 04 00 00 00 37")


def test_5_6_6_cml_command_without_id_goes_to_the_addressed_motor() -> None:
    wire = Wire(motors=2, K81_1=1, K84_2=-4)
    wire.transact(frame("04 10 00 66 00 02 04 29 0D 00 00"))   # ")" to address 4
    assert wire.chain.snapshot(2).status == 16 and wire.chain.snapshot(1).status == 8


# -- 5.6.2 silent interval -----------------------------------------------------------------
@pytest.mark.parametrize("k20, table_ms", [(1, 6.66), (2, 3.33), (0, 1.66), (3, 1.11),
                                           (4, 0.55), (5, 0.27)])
def test_5_6_2_a_message_ends_after_the_silent_interval(k20: int, table_ms: float) -> None:
    wire = Wire(K81_1=1, K20_1=k20)
    baud = {0: 38400, 1: 9600, 2: 19200, 3: 57600, 4: 115200, 5: 230400}[k20]
    gap = silent_interval_ns(baud)
    assert gap == gap_ns(baud) and abs(gap / 1e6 - table_ms) < 0.01
    request, reply = frame("01 03 00 C8 00 02"), frame("01 03 04 00 00 00 00")
    wire.send(request[:3])                         # a pause just under the interval
    wire.idle(gap - 1)
    assert wire.transact(request[3:]) == reply
    wire.send(request[:3])                         # a pause of the interval: two messages
    wire.idle(gap)
    assert wire.transact(request[3:]) == b""
    wire.send(request)                             # the reply comes one interval after
    wire.idle(gap - 1)
    assert wire.out == b""
    wire.idle(1)
    assert bytes(wire.out) == reply


# -- 5.6.9 Termination of Modbus mode ---------------------------------------------------------
def test_5_6_9_k81_0_written_by_modbus_returns_to_rs232() -> None:
    wire = Wire(K81_1=1)
    assert wire.text("?96.1") == ""                          # Modbus mode: no echo, no reply
    request = frame("01 10 03 6A 00 02 04 00 00 00 00")      # K81 at K78+874 := 0
    assert wire.transact(request) == frame("01 10 03 6A 00 02")
    assert wire.text("?96.1") == "?96.1\r\nPx.1=0\r\n"


def test_5_6_9_nine_f_escape_to_the_text_line_until_k81_is_written() -> None:
    wire = Wire(K81_1=1)
    assert wire.text("FFFFFFFF") == ""                       # eight are not enough
    assert wire.transact(frame("01 03 00 C8 00 02")) == frame("01 03 04 00 00 00 00")
    for _ in range(9):                                       # typed one by one
        wire.transact(b"F", wait_ns=ms(200))
    assert wire.text("?96.1") == "?96.1\r\nPx.1=0\r\n"        # temporarily RS-232
    assert wire.chain.get_param(1, 81) == 1
    assert wire.text("K81.1=1") == "K81.1=1\r\n"             # written: Modbus again
    assert wire.transact(frame("01 03 00 C8 00 02")) == frame("01 03 04 00 00 00 00")
    assert wire.text("FFFFFFFFFK81.1=0") == "K81.1=0\r\n"     # one burst: escape, then text
    assert wire.text("?99.1") == "?99.1\r\nUx.1=8\r\n"


def test_5_6_9_reports_are_not_sent_in_modbus_mode() -> None:
    wire = Wire(K81_1=1)
    wire.chain.execute("S.1=100, A.1=100, P.1=500, ^.1")
    wire.idle(seconds(1))
    assert wire.chain.snapshot(1).position == 500
    assert wire.out == b"" and any(e.text == "Ux.1=8" for e in wire.events)


# -- 5.6.1 wire time ------------------------------------------------------------------------
def test_5_6_1_paced_round_trip_is_wire_time_plus_the_silent_interval() -> None:
    """With pacing the request arrives after its wire time (10 bits a byte at K20), the
    motor answers one 5.6.2 interval later, and the answer takes its own wire time."""
    chain = Chain(pacing=True)
    chain.set_param(1, 81, 1)
    chain.set_param(1, 20, 4)                               # 115.2 kbps
    got = bytearray()
    chain.host_line.add_listener(got.extend)
    request, reply = frame("01 03 00 C8 00 02"), frame("01 03 04 00 00 00 00")
    start = chain.kernel.now
    chain.host_line.feed(request)
    assert chain.kernel.run_until(lambda: len(got) == len(reply), ms(50))
    byte = 10 * 1_000_000_000 // 115200
    assert bytes(got) == reply
    assert chain.kernel.now - start == len(request) * byte + gap_ns(115200) + len(reply) * byte
