"""Golden tests of the bridge's drive flows, sans IO (object writes in, exact values out).

ethercat-bridge-users-guide.txt Appendix 1 (CMD mode), Appendix 2 (CML over the
mailbox), Appendix 3 (mode switches), Appendix 4 (homing), 6.1 (CiA402 states),
6.3 (csp), 6.5 (digital I/O), 7.1 (CPIO), 7.3-7.5 (F511h, F530h, 60F6h, 60FBh).
The bench runs four virtual motors in virtual time; nothing here touches a network.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from coolmuscle.frontends.ethercat.engine.dictionary import (
    DEVICE_STATE,
    LENGTH_HIGH,
    NO_SUBINDEX,
    VALUE_HIGH,
    VALUE_LOW,
    VALUE_RANGE,
)
from ethercat_drive_support import Bench

STOPPERS = Path(__file__).parent / "data" / "ethercat_stoppers.toml"
NULL = "Null\r\n"


def high(word: int) -> int:
    return word >> 8


@pytest.fixture
def bench() -> Bench:
    return Bench("EB02", machine=STOPPERS)


# -- 6.1 CiA402 states -------------------------------------------------------------------
def test_6_1_power_up_csp_switch_on_disabled_then_06_07_0f_operation_enabled():
    b = Bench("EB02")
    assert b.read(0x6061) == 8 and b.read(0x6502) == 0xA0          # 6.2.1: hm, csp
    for axis in (1, 2, 3, 4):
        assert b.status(axis) == 0x0240                            # SOD + remote
    expected = {0x06: 0x0221, 0x07: 0x0223, 0x0F: 0x1227}          # RTSO, SO, OE+following
    for cw, sw in expected.items():
        for axis in (1, 2, 3, 4):
            b.pdo(axis, cw, b.position(axis))
        b.cycles(2)
        assert [b.status(a) for a in (1, 2, 3, 4)] == [sw] * 4
    assert b.axis(1).transitions == [1, 2, 3, 4]
    assert all(b.chain.snapshot(a).enabled for a in (1, 2, 3, 4))  # state B/C: motor enable


def test_6_1_1_state_a_frees_the_motor_and_state_b_enables_it():
    b = Bench("EB02")
    b.enable((1,))
    b.pdo(1, 0x06)                                                 # 8: shut down -> State A
    b.cycles(2)
    assert b.status(1) == 0x8221 and not b.chain.snapshot(1).enabled
    b.pdo(1, 0x07)                                                 # 3: switch on -> State B
    b.cycles(2)
    assert b.status(1) == 0x0223 and b.chain.snapshot(1).enabled
    b.pdo(1, 0x00)                                                 # 10: disable voltage
    b.cycles(2)
    assert b.status(1) == 0x8240 and b.axis(1).transitions[-1] == 10


def test_6_1_1_quick_stop_is_ignored():
    b = Bench("EB02")
    b.enable((1,))
    b.pdo(1, 0x0B)                                                 # quick stop (bit 2 = 0)
    b.cycles(3)
    assert b.status(1) == 0x1227 and b.axis(1).transitions == [1, 2, 3, 4]


def test_6_1_motor_alarm_is_fault_and_fault_reset_clears_it():
    b = Bench("EB02")
    b.enable((1,))
    b.chain.inject_fault(1, "over_current")                        # Ux = 64: an alarm
    b.cycles(1)
    assert b.status(1) == 0xC20F                                   # fault reaction active
    b.cycles(1)
    assert b.status(1) == 0xC208                                   # fault, error, free
    assert b.axis(1).transitions[-2:] == [13, 14]
    assert b.read(0xF530, 5) == 64                                 # 7.4 CM status
    b.pdo(1, 0x0F)
    b.cycles(2)
    assert b.status(1) == 0xC208                                   # no edge: still fault
    b.pdo(1, 0x80)                                                 # 15: fault reset 0 -> 1
    b.cycles(2)
    assert b.status(1) == 0xC240                   # SOD, free; the alarm stays latched ...
    b.pdo(1, 0x06)
    b.cycles(2)
    b.pdo(1, 0x07)                                 # ... until state B enables the motor
    b.cycles(2)                                    # (6.1.1 State C note 1)
    assert b.status(1) == 0x0223 and b.chain.execute("?99.1") == ["Ux.1=8"]
    b.enable((1,))
    assert b.status(1) == 0x1227


# -- 6.3 csp ----------------------------------------------------------------------------
def test_6_3_csp_follows_the_target_every_cycle_on_all_axes():
    b = Bench("EB02")
    b.enable()
    lags = []
    for i in range(1, 1001):                                       # 4,000 pulses in 1 s
        for axis in (1, 2, 3, 4):
            b.pdo(axis, 0x0F, 4 * i)
        b.cycles(1)
        lags.append(4 * i - b.position(1))
    assert max(lags) < 100 and all(abs(b.position(a) - 4000) < 50 for a in (1, 2, 3, 4))
    b.cycles(200)
    assert [b.position(a) for a in (1, 2, 3, 4)] == [4000] * 4
    assert [b.status(a) for a in (1, 2, 3, 4)] == [0x1227] * 4


def test_appendix_5_target_beyond_the_resolution_maximum_is_held_at_it():
    b = Bench("EB02")
    b.enable((1,))
    follower = b.axis(1).follower
    b.pdo(1, 0x0F, 2_000_000_000)
    b.cycles(1)
    assert follower._last == 42_949_672                            # K37 default: 1000 ppr


# -- 6.2 / Appendix 3 mode switches -------------------------------------------------------
@pytest.mark.parametrize("mode", [6, 101, 120, 121])
def test_appendix_3_mode_switch_shows_in_6061_after_5ms(mode):
    b = Bench("EB02")
    assert b.switch_mode(mode) == 5
    assert b.read(0x6061) == mode and b.read(0x6861) == 8          # per axis


def test_6_2_2_note3_unavailable_mode_falls_back_to_csp():
    b = Bench("EB02")
    b.switch_mode(6)
    b.write(0x6060, 0, 7)                                          # ip: not available
    b.cycles(6)
    assert b.read(0x6061) == 8


def test_6_2_2_switches_5ms_apart_and_only_where_the_diagram_allows():
    b = Bench("EB02")
    b.write(0x6060, 0, 6)
    b.cycles(1)
    assert b.read(0x6061) == 6
    b.write(0x6060, 0, 8)
    b.cycles(1)
    assert b.read(0x6061) == 6                                     # note 2: 5 ms apart
    b.cycles(4)
    assert b.read(0x6061) == 8
    b.switch_mode(120)
    assert b.abort(0x6060, 0, 8) == DEVICE_STATE                   # CMD -> csp: "x"
    assert b.abort(0x6060, 0, 6) == DEVICE_STATE                   # CMD -> hm: "x"
    b.switch_mode(101)
    b.switch_mode(8)                                               # via CML (note 2)
    assert b.read(0x6061) == 8


def test_6_2_2_note1_mode_switch_while_moving_is_refused():
    b = Bench("EB02")
    b.enable((1,))
    for i in range(1, 30):
        b.pdo(1, 0x0F, 40 * i)
        b.cycles(1)
    assert b.abort(0x6060, 0, 6) == DEVICE_STATE
    b.cycles(300)                                                  # at rest on target
    assert b.abort(0x6060, 0, 6) == 0


# -- Appendix 1: CMD mode ------------------------------------------------------------------
def _cmd(b: Bench, word: int) -> int:
    """Appendix 1: 0007h, 5 cycles, the command, 5 cycles; the statusword."""
    b.pdo(1, 0x0007)
    b.cycles(5)
    b.pdo(1, word)
    b.cycles(5)
    return b.status(1)


def test_appendix_1_1_origin_search_f307_acknowledged_f3_then_f8(bench):
    b = bench
    b.switch_mode(120)
    assert high(_cmd(b, 0xF307)) == 0xF3                           # during origin search
    b.until(lambda: high(b.status(1)) != 0xF3, 20000)
    assert high(b.status(1)) == 0xF8                               # completion
    assert b.chain.snapshot(1).extra["origin_done"] == 1 and b.position(1) == 0
    b.pdo(1, 0x0007)
    b.cycles(5)
    assert high(b.status(1)) != 0xF8                               # command completed


def test_appendix_1_1_origin_search_without_a_stopper_times_out_f9():
    from coolmuscle.frontends.ethercat.bridge import homing
    b = Bench("EB02")
    b.switch_mode(120)
    assert high(_cmd(b, 0xF307)) == 0xF3
    b.kernel.run(until=b.kernel.now + homing.TIMEOUT_NS)            # nothing to find
    b.cycles(2)
    assert high(b.status(1)) == 0xF9
    assert b.chain.snapshot(1).extra["origin_search"] == 0         # stopped


def test_appendix_1_2_motor_free_f107_f1(bench):
    bench.switch_mode(120)
    assert high(_cmd(bench, 0xF107)) == 0xF1 and not bench.chain.snapshot(1).enabled


def test_appendix_1_4_motor_enable_f207_f2(bench):
    bench.switch_mode(120)
    _cmd(bench, 0xF107)
    assert high(_cmd(bench, 0xF207)) == 0xF2 and bench.chain.snapshot(1).enabled


def test_appendix_1_3_reset_counter_f407_f4(bench):
    b = bench
    b.chain.execute("S.1=10,A.1=100,P.1=500,^.1")
    b.cycles(1500)
    assert b.position(1) == 500
    b.switch_mode(120)
    assert high(_cmd(b, 0xF407)) == 0xF4 and b.position(1) == 0


def test_appendix_1_5_origin_search_abort_f607_f6(bench):
    b = bench
    b.switch_mode(120)
    _cmd(b, 0xF307)
    b.cycles(50)
    assert b.chain.snapshot(1).extra["origin_search"] == 1
    assert high(_cmd(b, 0xF607)) == 0xF6
    assert b.chain.snapshot(1).extra["origin_search"] == 0


# -- Appendix 2: CML over the mailbox -----------------------------------------------------------
def _cml_mode(b: Bench) -> None:
    b.switch_mode(101)
    b.pdo(1, 0x0000)                                               # "Set 0000h", 5 cycles
    b.cycles(5)


def test_appendix_2_1_read_k53_null_until_the_reply_has_crossed_the_cm_port():
    b = Bench("EB01")
    _cml_mode(b)
    b.write(0xF581, 0, "K53.1")
    assert b.read(0xF591) == NULL                                  # not there yet
    b.cycles(1)
    assert b.read(0xF591) == NULL                                  # 1 ms: still crossing
    b.cycles(2)
    assert b.read(0xF591) == "K53.1=0\r\n"
    assert b.read(0xF591) == NULL
    assert b.drive.mailboxes[1].sent == ["K53.1"]


def test_appendix_2_2_write_parameter_reaches_the_motor():
    b = Bench("EB02")
    _cml_mode(b)
    b.write(0xF581, 0, "K42.1=100")                                # Appendix 2.2's flow
    b.cycles(5)
    assert b.read(0xF591) == NULL                                  # an assignment: no reply
    assert b.chain.get_param(1, 42) == 100
    b.cycles(100)
    assert b.read(0x60F6, 0x16) == 100                             # 60F6h sees it too (7.5)


def test_appendix_2_3_query_99():
    b = Bench("EB02")
    _cml_mode(b)
    b.write(0xF581, 0, "?99.1")
    b.cycles(3)
    assert b.read(0xF591) == "Ux.1=8\r\n"


def test_appendix_2_4_origin_search_reports_origin(bench):
    b = bench
    _cml_mode(b)
    b.write(0xF581, 0, "|.1")
    b.cycles(2)
    assert b.read(0xF591) == NULL
    lines: list[str] = []
    b.until(lambda: lines.append(b.read(0xF591)) or lines[-1].startswith("Origin"), 20000)
    assert lines[-1] == "Origin.1=0\r\n"
    b.cycles(2)                                                    # the next line crossing
    assert b.read(0xF591) == "Ux.1=8\r\n"
    assert set(lines[:-1]) == {NULL}


def test_appendix_2_5_query_90_multiple_lines_polled_every_10ms_until_null():
    b = Bench("EB02")
    _cml_mode(b)
    expected = [line + "\r\n" for line in b.chain.execute("?90.1", origin="web")]
    b.write(0xF581, 0, "?90.1")
    b.cycles(5)
    got = []
    while (line := b.read(0xF591)) != NULL:
        got.append(line)
        b.cycles(10)
    assert got == expected and len(got) == 18                      # K20..K89, 4 a line


def test_appendix_2_6_outputs_on_off_show_on_the_motors_own_line():
    b = Bench("EB02")
    _cml_mode(b)
    b.write(0xF581, 0, "K34.1=3333")                               # outputs: general use
    b.cycles(8)
    b.write(0xF581, 0, "O1.1,O2.1,F3.1,O4.1")
    b.cycles(8)
    assert b.chain.execute("?50.1", origin="host") == ["OUT.1=0B"]


def test_7_2_2_string_over_64_bytes_is_refused_and_an_error_line_comes_back():
    b = Bench("EB02")
    _cml_mode(b)
    assert b.abort(0xF581, 0, b"?99.1," * 11) == LENGTH_HIGH
    b.write(0xF581, 0, "K23.1=17")                                 # messages on
    b.cycles(5)
    b.write(0xF581, 0, "K99.1=5")
    b.cycles(5)
    own = b.chain.execute("K99.1=5", origin="web")                 # the motor's own answer
    assert own and own[0].startswith("error") and b.read(0xF591) == own[0] + "\r\n"
    assert b.abort(0xF581, 0, "?99.1") == 0


def test_7_1_1_cml_strings_need_cml_mode():
    b = Bench("EB02")
    assert b.abort(0xF581, 0, "?99.1") == DEVICE_STATE
    assert b.read(0xF591) == NULL


def test_7_2_2_replies_and_reports_queue_in_order_and_none_is_lost():
    b = Bench("EB02")
    _cml_mode(b)
    b.write(0xF581, 0, "?96.1,?99.1,?97.1")
    b.cycles(6)
    assert [b.read(0xF591) for _ in range(4)] == ["Px.1=0\r\n", "Ux.1=8\r\n", "Sx.1=0\r\n",
                                                  NULL]


# -- Appendix 4: homing --------------------------------------------------------------------------
@pytest.mark.parametrize("method,speed_sub", [(1, 2), (2, 2)])
def test_appendix_4_homing_on_a_stopper_ends_with_bits_10_and_12(bench, method, speed_sub):
    b = bench
    b.switch_mode(6)
    b.enable((1,))
    assert b.status(1) & 0x3400 == 0x0400                          # not started: bit 10
    b.write(0x6098, 0, method)
    b.write(0x6099, speed_sub, 60)
    b.write(0x609A, 0, 200)
    b.write(0x607C, 0, 0)
    b.cycles(100)                                                  # "Wait 100msec"
    b.pdo(1, 0x1F)                                                 # bit 4: 0 -> 1
    b.cycles(5)
    assert b.status(1) & 0x3400 == 0                               # homing in progress
    b.until(lambda: b.status(1) & 0x3000, 20000)                   # monitoring, bit 13/12
    assert b.status(1) & 0x3400 == 0x1400
    b.pdo(1, 0x0F)
    b.cycles(5)
    assert b.position(1) == 0 and b.status(1) & 0x3400 == 0x1400
    k45 = b.chain.get_param(1, 45)
    assert (b.chain.get_param(1, 42), k45 % 10, b.chain.get_param(1, 43)) == \
        (60, 0 if method == 1 else 1, 200)


def test_appendix_4_homing_on_the_origin_switch_method_4():
    b = Bench("EB02", machine=Path(__file__).parent / "data" / "ethercat_origin_sensor.toml")
    b.switch_mode(6)
    b.enable((1,))
    b.write(0x6098, 0, 4)                                          # switch CCW
    b.write(0x6099, 1, 50)                                         # speed for the switch
    b.cycles(100)
    b.pdo(1, 0x1F)
    b.until(lambda: b.status(1) & 0x3000, 20000)
    assert b.status(1) & 0x3400 == 0x1400
    assert (b.chain.get_param(1, 46), b.chain.get_param(1, 42)) == (2, 50)
    b.cycles(50)
    assert b.position(1) == 0 and b.chain.snapshot(1).inputs & 1     # at the switch


def test_6_4_1_homing_objects_refuse_values_the_motor_refuses():
    b = Bench("EB01")
    assert b.abort(0x6098, 0, 5) == VALUE_HIGH and b.abort(0x6098, 0, 0) == VALUE_LOW
    assert b.abort(0x6099, 1, 5001) == VALUE_HIGH                  # CM1 K42 1..5000
    assert b.abort(0x609A, 0, 0) == VALUE_LOW                      # K43 1..5000
    # 607Ch is "U32" (6.4.1) carrying the signed K48 (-32767..32767), as 60F6h does
    assert b.abort(0x607C, 0, -40000 & 0xFFFFFFFF) == VALUE_LOW
    assert b.abort(0x607C, 0, 40000) == VALUE_HIGH
    assert b.abort(0x607C, 0, -300 & 0xFFFFFFFF) == 0
    b.cycles(1)
    assert b.chain.get_param(1, 48) == -300 and b.read(0x607C) == 0xFFFFFED4
    assert b.read(0x60F6, 0x1C) == 0xFFFFFED4                     # the same K48


def test_appendix_6_table_details():
    """7.3 F511h-F514h: "Number of Entries 4: Fixed" (4h reserved, N/A); 6.4.1 60E3h
    INT16 entries (the methods 1-4 of 6098h); 7.2.2 F591h-F594h "Max String Size
    64bytes" (a longer reply is read in 64-byte pieces)."""
    from coolmuscle.frontends.ethercat.engine.od import INT16
    b = Bench("EB12")
    assert [b.read(0xF511 + i, 0) for i in range(4)] == [4, 4, 4, 4]
    assert [b.read(0x60E3, s) for s in range(1, 5)] == [1, 2, 3, 4]
    assert all(b.od.lookup(0x60E3 + 0x800 * a, s)[1].dtype == INT16
               for a in range(4) for s in range(1, 5))
    assert all(b.od.table.get(0xF591 + i).entries[0].bits == 64 * 8 for i in range(4))


# -- 6.5 digital I/O, 7.1 CPIO --------------------------------------------------------------
def test_6_5_digital_io_in_csp_state_b_or_c():
    b = Bench("EB02")
    assert b.abort(0x60FD, 0) == DEVICE_STATE                      # state A
    b.write(0x60F6, 0x0E, 3333)                                    # K34: general use
    b.enable((1,))
    b.chain.set_input(1, 2, True)
    b.chain.set_input(1, 6, True)
    b.cycles(1)
    assert b.read(0x60FD) == 0b100010
    b.write(0x60FE, 2, 0b0101)                                     # mask: OUT1, OUT3
    b.write(0x60FE, 1, 0b1111)
    b.cycles(1)
    assert b.chain.execute("?50.1", origin="host") == ["OUT.1=05"]


def test_6_5_cm1_input1_and_output1_carry_the_serial_line():
    b = Bench("EB01")
    b.enable((1,))
    for n in (1, 2, 4):
        b.chain.set_input(1, n, True)
    b.cycles(1)
    assert b.read(0x60FD) == 0b1010


def test_7_1_cpio_outputs_from_bits_4_7_and_inputs_in_bits_4_7():
    b = Bench("EB02")
    b.write(0x60F6, 0x0E, 3333)
    b.cycles(2)
    b.switch_mode(121)
    for cw in (0xC006, 0xC007, 0xC00F):
        b.pdo(1, cw, b.position(1))
        b.cycles(2)
    b.pdo(1, 0xC05F)                                               # OUT1 + OUT3 on
    b.chain.set_input(1, 3, True)
    b.cycles(2)
    assert b.chain.execute("?50.1", origin="host") == ["OUT.1=05"]
    assert b.status(1) == 0xC000 | 0x8 << 8 | 0b0100 << 4 | 0x7    # in-position, IN3, OE
    b.pdo(1, 0xC01F)
    b.cycles(2)
    assert b.chain.execute("?50.1", origin="host") == ["OUT.1=01"]


# -- 7.3-7.5 settings and status ------------------------------------------------------------
def test_7_3_f511_cm_type_baud_rate_and_cycle_codes():
    b = Bench("EB12")
    assert [b.read(0xF511 + i, 1) for i in range(4)] == [1, 1, 2, 2]
    assert b.read(0xF511, 2) == 6 and b.read(0xF511, 3) == 1       # 176,800 bps, 1 ms


def test_7_4_f530_counts_the_cm_port_and_the_pdo_cycle():
    b = Bench("EB02")
    before = b.read(0xF530, 9)
    b.cycles(10)
    assert b.read(0xF530, 9) - before == 10 and b.read(0xF530, 0x0D) >= 10
    assert b.read(0xF530, 1) == 0
    for _ in range(5):
        b.pdo(1, 0)
        b.cycles(1)
    assert b.read(0xF530, 0x11) == 1000 and b.read(0xF530, 0x12) == 1000
    b.kernel.run(until=b.kernel.now + 2_000_000)
    b.pdo(1, 0)
    assert b.read(0xF530, 0x11) == 3000 and b.read(0xF530, 0x13) == 1


def test_7_5_k_parameters_through_60f6_and_servo_stiffness_60fb():
    b = Bench("EB12")
    assert b.read(0x60F6, 0) == 0x4F and b.read(0x60F6, 0x16) == 100         # CM1 K42
    assert b.read(0x70F6, 0x16) == 10           # CM2 K42 (6.4.1 Note1: 100 / 10 default)
    assert b.abort(0x60F6, 0x01, 0) == NO_SUBINDEX                            # K21: N/A
    assert b.abort(0x60F6, 0x16, 0) == VALUE_LOW
    assert b.abort(0x70F6, 0x30, 2) == VALUE_HIGH                            # CM2 K68 0..1
    b.write(0x60F6, 0x1C, (-5) & 0xFFFFFFFF)                                  # K48 = -5
    b.cycles(1)
    assert b.chain.get_param(1, 48) == -5 and b.read(0x60F6, 0x1C) == 0xFFFFFFFB
    assert b.abort(0x60FB, 1) != 0                                            # CM1: none
    b.write(0x70FB, 1, 1234)
    b.cycles(1)
    assert b.chain.get_register(3, "H", 0) == 1234 and b.read(0x70FB, 1) == 1234
    assert b.abort(0x70FB, 1, 40000) == VALUE_HIGH
    assert b.abort(0x70F6, 0x2C, 99) in (VALUE_HIGH, VALUE_RANGE)             # CM2 K64


def test_7_1_2_cpio_on_cm1_drives_out2_only_and_reports_input2_4():
    b = Bench("EB12")                                              # ID1: CM1
    sent: list[str] = []                       # the bridge's own lines to ID1 (Axis.send)
    real_execute = b.chain.execute

    def execute(text: str, *args: Any, **kwargs: Any) -> Any:
        if kwargs.get("origin") == "api" and kwargs.get("motor") == 1:
            sent.append(text)
        return real_execute(text, *args, **kwargs)
    b.chain.execute = execute  # type: ignore[method-assign]
    b.switch_mode(121)
    for cw in (0xC006, 0xC007, 0xC00F):
        b.pdo(1, cw, b.position(1))
        b.cycles(2)
    b.pdo(1, 0xC0FF)                                               # OUT1-OUT4 asked ...
    b.cycles(2)
    b.pdo(1, 0xC00F)                                               # ... and all off
    b.cycles(2)
    outputs = [t for t in sent if t[0] in "OF"]
    assert outputs and all(part[:2] in ("O2", "F2") for t in outputs for part in t.split(","))
    b.chain.set_input(1, 1, True)                                  # INPUT1: the serial line
    b.chain.set_input(1, 2, True)
    b.cycles(2)
    assert (b.status(1) >> 4) & 0x0F == 0b0010                     # INPUT2 only
