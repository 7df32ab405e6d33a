"""K parameters and firmware profiles against the manuals' own numbers."""

from __future__ import annotations

import dataclasses

import pytest

from coolmuscle.errors import OutOfRangeError
from coolmuscle.motor.state.firmware import CM1, CM2, FIRMWARES, RT3, get_firmware
from coolmuscle.motor.state.param_table import NoSuchParameterError, ParamTable
from coolmuscle.motor.state.units import RESOLUTIONS

# Table 6.1 (cml-users-guide.txt), typed in again by hand: k -> (min, max, default).
TABLE_6_1 = {
    20: (0, 5, 0), 23: (0, 31, 1), 24: (10, 50000, 1000), 25: (111111, 999999, 333333),
    26: (0, 333333, 0), 27: (0, 999999, 0), 28: (0, 999999, 0), 29: (0, 999999, 0),
    30: (0, 999999, 0), 31: (0, 999999, 0), 32: (0, 999999, 0), 33: (0, 1111, 1111),
    34: (0, 9999, 0), 35: (0, 9, 0), 36: (0, 3, 0), 37: (0, 90, 3), 38: (0, 10, 1),
    39: (0, 1024, 128), 41: (-999999999, 999999999, 200), 42: (1, 32767, 10),
    43: (1, 32767, 100), 44: (1, 500, 100), 45: (0, 223, 1), 46: (0, 7, 0),
    47: (10, 150, 30), 48: (-32767, 32767, 0), 49: (1, 32767, 10), 50: (1, 100, 10),
    51: (0, 1000, 0), 55: (1, 100, 5), 56: (1, 32767, 50), 57: (100, 10000, 3000),
    58: (0, 999999999, 0), 59: (-999999999, 0, 0), 60: (10, 100, 30),
    61: (0, 30000, 200), 62: (0, 30, 0), 63: (0, 30000, 100), 64: (0, 1, 0),
    65: (0, 5, 0), 68: (0, 1, 1), 69: (0, 1024, 0), 70: (0, 1, 1), 71: (0, 7, 0),
    72: (0, 32767, 400), 73: (1, 1000, 10), 74: (0, 1000, 100), 75: (0, 500, 10),
    76: (0, 500, 250), 77: (-1000, 1000, 200), 78: (-1, 32767, 0), 79: (-1, 32767, 0),
    80: (0, 32767, 0), 81: (-255, 255, 0), 82: (0, 2, 0), 84: (-256, 1, 0),
    85: (0, 3, 0),  # printed "Min 3 Max 0"
}
NOT_IN_TABLE_6_1 = (21, 22, 52, 53, 54, 66, 67, 83, 86, 87, 88, 89)


@pytest.fixture
def table() -> ParamTable:
    return ParamTable()


def test_6_1_every_parameter_min_max_default(table: ParamTable) -> None:
    for k, (lo, hi, default) in TABLE_6_1.items():
        spec = table.spec(k)
        assert (spec.min, spec.max, spec.default) == (lo, hi, default), k
        assert table.get(k) == default
        assert not spec.reserved


def test_6_1_range_boundaries_accepted_and_one_beyond_refused(table: ParamTable) -> None:
    for k, (lo, hi, _default) in TABLE_6_1.items():
        if table.spec(k).kind != "range":
            continue
        table.set(k, lo)
        table.set(k, hi)
        for bad in (lo - 1, hi + 1):
            with pytest.raises(OutOfRangeError):
                table.set(k, bad)
            assert table.get(k) == hi, f"K{k}={bad} was reflected"


def test_3_out_of_range_value_is_not_reflected(table: ParamTable) -> None:
    table.set(24, 1000)
    with pytest.raises(OutOfRangeError) as info:
        table.set(24, 9)
    assert table.get(24) == 1000
    assert info.value.motor_line(1) == "error00.1: Out Of Range!!"


def test_k24_min_10_max_50000(table: ParamTable) -> None:
    table.set(24, 10)
    table.set(24, 50000)
    for bad in (9, 50001, 32767 * 2):
        with pytest.raises(OutOfRangeError):
            table.set(24, bad)


def test_k25_each_digit_1_to_9(table: ParamTable) -> None:
    table.set(25, 976532)  # ch. 3 K25 setting example
    assert table.get(25) == 976532
    for bad in (976530, 906532, 33333, 1111111, 0, -333333):
        with pytest.raises(OutOfRangeError):
            table.set(25, bad)
    assert table.get(25) == 976532


def test_k26_each_digit_0_to_3(table: ParamTable) -> None:
    table.set(26, 10)       # ch. 3 "K26.1 = 000010"
    table.set(26, 200000)   # "2XXX00"
    table.set(26, 22)       # "XXXX22"
    table.set(26, 333333)
    for bad in (4, 40, 400000, 1000000, -1):
        with pytest.raises(OutOfRangeError):
            table.set(26, bad)
    assert table.get(26) == 333333


def test_k27_to_k32_each_digit_0_to_9(table: ParamTable) -> None:
    table.set(27, 871243)   # ch. 3 K27 example
    table.set(28, 987612)   # ch. 3 K28 example
    table.set(29, 987612)   # ch. 3 K29 example
    for k in range(27, 33):
        table.set(k, 999999)
        with pytest.raises(OutOfRangeError):
            table.set(k, 1000000)
        with pytest.raises(OutOfRangeError):
            table.set(k, -1)


def test_k33_four_digits_0_or_1(table: ParamTable) -> None:
    table.set(33, 1)        # ch. 3 "K33.1 = 0001"
    table.set(33, 1010)
    for bad in (2, 1012, 11111, 9999):
        with pytest.raises(OutOfRangeError):
            table.set(33, bad)
    assert table.get(33) == 1010


def test_k34_four_digits_0_to_9(table: ParamTable) -> None:
    table.set(34, 2177)     # ch. 3 "K34.1=2177"
    with pytest.raises(OutOfRangeError):
        table.set(34, 12177)
    assert table.get(34) == 2177


def test_k45_digit_ranges(table: ParamTable) -> None:
    table.set(45, 102)      # ch. 3 "K45.1=102"
    table.set(45, 223)
    table.set(45, 3)
    for bad in (4, 104, 130, 302, 224, 1000, -1):
        with pytest.raises(OutOfRangeError):
            table.set(45, bad)
    assert table.get(45) == 3


def test_k37_only_table_values(table: ParamTable) -> None:
    for k37 in RESOLUTIONS:
        if k37 <= 90:
            table.set(37, k37)
    for bad in (9, 29, 89, 11, 19, 31, 39, 51, 59, 71, 79, 91, -1, 100):
        with pytest.raises(OutOfRangeError):
            table.set(37, bad)


def test_k40_max_depends_on_motor_type_choice(table: ParamTable) -> None:
    spec = table.spec(40)
    assert (spec.min, spec.max, spec.default) == (1, 4000, 3000)


def test_k85_endian_accepts_0_to_3_despite_swapped_print(table: ParamTable) -> None:
    for v in range(4):
        table.set(85, v)
    with pytest.raises(OutOfRangeError):
        table.set(85, 4)


def test_k80_minus_one_refused_because_table_min_is_0(table: ParamTable) -> None:
    with pytest.raises(OutOfRangeError):
        table.set(80, -1)
    table.set(78, -1)
    table.set(79, -1)


def test_reserved_numbers_read_fixed_values_and_refuse_others(table: ParamTable) -> None:
    for k in NOT_IN_TABLE_6_1:
        spec = table.spec(k)
        assert spec.reserved
        expected = 200 if k == 22 else 0
        assert table.get(k) == expected
        table.set(k, expected)  # writing the value it has is accepted
        with pytest.raises(OutOfRangeError):
            table.set(k, expected + 1)
        assert table.get(k) == expected


def test_unknown_k_number(table: ParamTable) -> None:
    for k in (19, 90, 0, -20, 1000):
        with pytest.raises(NoSuchParameterError) as info:
            table.set(k, 0)
        assert isinstance(info.value, OutOfRangeError)
        assert isinstance(info.value, LookupError)
        with pytest.raises(LookupError):
            table.get(k)


def test_non_integer_values_refused(table: ParamTable) -> None:
    for bad in (1.0, "1", True, None):
        with pytest.raises(OutOfRangeError):
            table.set(20, bad)  # type: ignore[arg-type]


def test_listeners_see_every_accepted_write(table: ParamTable) -> None:
    seen: list[tuple[int, int, int]] = []
    remove = table.on_change(lambda k, old, new: seen.append((k, old, new)))
    table.set(70, 0)
    table.set(70, 0)                 # unchanged value: still reported
    with pytest.raises(OutOfRangeError):
        table.set(70, 2)             # refused: not reported
    table.set(65, 5)
    assert seen == [(70, 1, 0), (70, 0, 0), (65, 0, 5)]
    remove()
    table.set(20, 1)
    assert len(seen) == 3


def test_listener_sees_new_value_already_applied(table: ParamTable) -> None:
    values: list[int] = []
    table.on_change(lambda k, old, new: values.append(table.get(k)))
    table.set(20, 4)
    assert values == [4]


def test_restore_skips_invalid_and_calls_no_listener(table: ParamTable) -> None:
    seen: list[int] = []
    table.on_change(lambda k, old, new: seen.append(k))
    rejected = table.restore({20: 3, 24: 5, 22: 7, 95: 1, 37: 23})
    assert rejected == [22, 24, 95]
    assert (table.get(20), table.get(24), table.get(22), table.get(37)) == (3, 1000, 200, 23)
    assert seen == []
    table.reset()
    assert table.values() == table.defaults()


def test_6_6_q90_listing_exact(table: ParamTable) -> None:
    lines = table.format_param_listing(1)
    assert lines[0] == "K20.1=0, K21.1=0, K22.1=200, K23.1=1"   # 6.6 ?90 example
    assert lines[-1] == "K88.1=0, K89.1=0"                      # 6.6 ?90 example
    assert len(lines) == 18
    assert lines[1] == "K24.1=1000, K25.1=333333, K26.1=0, K27.1=0"
    assert lines[3] == "K32.1=0, K33.1=1111, K34.1=0, K35.1=0"
    table.set(70, 0)
    assert "K70.3=0" in table.format_param_listing(3)[12]
    assert table.format_param(70, 3) == "K70.3=0"


def test_items_in_k_order(table: ParamTable) -> None:
    ks = [k for k, _ in table.items()]
    assert ks == list(range(20, 90))


# -- firmware profiles -----------------------------------------------------------

def test_firmware_lookup_by_name() -> None:
    assert get_firmware("cm2") is CM2
    assert get_firmware("RT3") is RT3
    assert get_firmware(" cm1 ") is CM1
    assert set(FIRMWARES) == {"cm2", "rt3", "cm1"}
    with pytest.raises(LookupError):
        get_firmware("cm3")


def test_6_6_q85_version_title_example() -> None:
    assert CM2.version_title(1) == "ID1 : CM2v3.10R.1 #0802A12345"
    unit = CM2.with_(motor_type="C", serial="1234B00001", hardware_no="2", version="3.20")
    assert unit.version_title(7) == "ID7 : CM2v3.20C.2 #1234B00001"
    assert not unit.has_interpolation and not unit.can_allocate
    assert CM2.has_interpolation and CM2.can_allocate


def test_firmware_io_and_registers() -> None:
    assert (CM2.inputs, CM2.outputs) == (6, 4)
    assert (CM1.inputs, CM1.outputs) == (4, 2)
    regs = CM2.registers
    assert [regs.limit(k) for k in "PSAMTVNRH"] == [200, 15, 8, 8, 8, 15, 200, 200, 0]
    regs = RT3.registers
    assert [regs.limit(k) for k in "PSAMTVNR"] == [25, 15, 7, 7, 7, 15, 25, 25]
    assert CM2.pnr_pool == 600 and RT3.pnr_pool is None
    assert CM2.max_bank_commands == 500 and RT3.max_bank_steps == 200
    assert CM2.is_servo and not CM1.is_servo


def test_ladder_parameters_per_firmware() -> None:
    assert (CM2.ladder_bank_k, CM2.ladder_period_k) == (62, 63)
    assert CM2.ladder_zero_disables
    rt3 = ParamTable(RT3)
    assert (RT3.ladder_bank_k, RT3.ladder_period_k) == (85, 87)
    assert not RT3.ladder_zero_disables
    rt3.set(85, 30)
    rt3.set(87, 1)
    rt3.set(87, 30000)
    for k, bad in ((85, 31), (87, 0), (87, 30001)):
        with pytest.raises(OutOfRangeError):
            rt3.set(k, bad)
    assert rt3.spec(62).reserved and rt3.spec(63).reserved
    assert ParamTable(CM1).spec(87).max == 32767


def test_rt3_per_input_parameters_have_four_digits() -> None:
    rt3 = ParamTable(RT3)
    assert rt3.get(25) == 3333 and rt3.get(33) == 11
    rt3.set(27, 9999)
    with pytest.raises(OutOfRangeError):
        rt3.set(27, 19999)


def test_cm1_appendix_a_values() -> None:
    cm1 = ParamTable(CM1)
    cm1.set(27, 2347)          # Appendix A "E.g. K27=2347"
    cm1.set(34, 82)            # Appendix A "E.g. K34=82"
    cm1.set(23, 32)            # 32: merge event (not in CM2)
    cm1.set(46, 19)
    cm1.set(52, 10)            # section 3.2.4 "K52=10"
    cm1.set(61, 30001)
    for k, bad in ((27, 12347), (34, 182), (46, 4), (52, 3), (60, 81), (39, 1029),
                   (37, 41), (37, 80), (22, 9), (20, 1)):
        with pytest.raises(OutOfRangeError):
            cm1.set(k, bad)
    with pytest.raises(OutOfRangeError):
        ParamTable(CM2).set(23, 32)


def test_6_7_u1_u2_examples() -> None:
    assert CM2.sine(3000) == 5000      # 6.7 U1 example
    assert CM2.cosine(3000) == 8660    # 6.7 U2 example
    assert CM2.sine(-3000) == -5000
    assert CM2.sine(4500) == 7071      # truncated, not rounded (7071.07)
    assert CM2.sine(-4500) == -7071
    assert CM2.cosine(9000) == 0
    assert CM2.sine(9000) == 10000
    assert CM2.sine(36000 + 3000) == 5000


def test_rt3_u1_scaling() -> None:
    assert RT3.sine(2500) == 10000     # a quarter of 10000 is 90 degrees
    assert RT3.cosine(5000) == -10000
    assert RT3.sine(1250) == 7071
    assert RT3.sine(3000) == 9510      # 10000 sin(0.6 pi) = 9510.56


def test_firmware_is_frozen_and_hashable() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        CM2.inputs = 3  # type: ignore[misc]
    assert hash(CM2) == hash(CM2.with_())
    assert CM2 == CM2.with_()
    assert CM2 != CM2.with_(motor_type="P")


def test_every_profile_defines_k20_to_k89_with_valid_defaults() -> None:
    for fw in FIRMWARES.values():
        table = ParamTable(fw)
        assert sorted(table.defaults()) == list(range(20, 90))
        assert len(table.format_param_listing(1)) == 18


def test_a_k_number_is_looked_up_by_value_whatever_its_type(table: ParamTable) -> None:
    """37.0 and numpy's 37 are K37 (as a dict key); "37" and None are no K number.  The
    same answers from the compiled table (coolmuscle/_accel.py) as from the sources."""
    import numpy as np
    seen: list[tuple[int, int, int]] = []
    table.on_change(lambda k, old, new: seen.append((k, old, new)))
    assert table.get(37.0) == table.get(37) == table.get(np.int64(37))  # type: ignore[arg-type]
    old = table.get(37)
    table.set(37.0, 23)                                   # type: ignore[arg-type]
    table.set(np.int64(37), 22)                           # type: ignore[arg-type]
    assert table.get(37) == 22
    assert seen == [(37, old, 23), (37, 23, 22)] and all(type(k) is int for k, _, _ in seen)
    for bad in ("37", None, 37.5, (37,)):
        with pytest.raises(NoSuchParameterError):
            table.get(bad)                                # type: ignore[arg-type]
        with pytest.raises(NoSuchParameterError):
            table.set(bad, 1)                             # type: ignore[arg-type]
    assert table.restore({20: True, 21: 1.0, 22: "1"}) == [20, 21, 22]
