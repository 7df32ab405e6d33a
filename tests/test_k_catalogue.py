"""The K-parameter catalogue (coolmuscle.motor.state.catalogue): table 6.1's meaning beside
the firmware tables' numbers, for every K20..K89 of CM2, RT3 and CM1."""

from __future__ import annotations

import pytest

from coolmuscle.motor.state.catalogue import catalogue, defined_on, k_parameter, same_parameter
from coolmuscle.motor.state.firmware import CM1, CM2, RT3, Firmware


@pytest.mark.parametrize("fw", [CM2, RT3, CM1], ids=lambda f: f.name)
def test_every_defined_k_has_a_meaning_and_the_tables_numbers(fw: Firmware) -> None:
    entries = catalogue(fw.name)
    assert [e.k for e in entries] == list(range(20, 90))
    for entry in entries:
        assert entry.spec == fw.spec(entry.k)
        assert bool(entry.meaning) == entry.defined, entry.k


def test_table_6_1_rows_as_a_reader_sees_them() -> None:
    k24 = k_parameter("cm2", 24)
    assert (k24.name, k24.unit, k24.default) == ("Rotation Pulse Output", "pulses", 1000)
    assert k24.describe() == "Rotation Pulse Output (pulses; 10..50000; factory 1000)"
    assert k_parameter("cm2", 45).range_text() == "000..223 digit by digit"
    assert k_parameter("cm2", 20).meaning.startswith("Baud rate between the motor and the host: "
                                                     "0 38.4 kbps, 1 9.6 kbps")
    assert k_parameter("cm2", 52).range_text() == "not defined (reads 0)"


def test_a_value_out_of_range_or_on_an_undefined_k_is_a_problem() -> None:
    assert k_parameter("cm2", 24).problem(1000) is None
    assert k_parameter("cm2", 24).problem(5) == "K24=5 is out of range (10..50000)"
    assert k_parameter("cm2", 25).problem(333303) == \
        "K25=333303 is out of range (111111..999999 digit by digit)"
    assert k_parameter("rt3", 62).problem(0) is None         # reserved, at its fixed value
    assert k_parameter("rt3", 62).problem(3) == "K62 is not defined on rt3 (it reads 0)"


def test_k85_is_another_parameter_on_rt3_and_cm1() -> None:
    assert k_parameter("cm2", 85).name == "Endian"
    assert k_parameter("rt3", 85).name == "Logic bank executed when powered on"
    assert not same_parameter(85, "cm2", "rt3")
    assert same_parameter(24, "cm2", "rt3")
    assert defined_on(62) == ("cm2",)
    assert defined_on(87) == ("rt3", "cm1")


def test_a_k_outside_20_to_89_does_not_exist() -> None:
    with pytest.raises(LookupError, match="K90 does not exist"):
        k_parameter("cm2", 90)
