"""Data registers (CML 2.1.1, 2.2.1, 6.2, 2.1.2 allocation, 5.6.7 H0)."""

from __future__ import annotations

import dataclasses
import json
import pickle

import pytest

from coolmuscle.errors import OutOfRangeError
from coolmuscle.motor.state.firmware import CM1, CM2, RT3
from coolmuscle.motor.state.memory import (
    Memory,
    NoSuchRegisterError,
    VNumber,
    VState,
    VString,
    parse_v_text,
    state_name,
)


@pytest.fixture
def mem() -> Memory:
    return Memory(CM2)


def refused(mem: Memory, kind: str, index: int, value: object) -> None:
    before = mem.get(kind, index)
    with pytest.raises(OutOfRangeError):
        mem.set(kind, index, value)
    assert mem.get(kind, index) == before


def test_2_1_operation_example_values(mem: Memory) -> None:
    mem.set("S", 0, 100)
    mem.set("A", 0, 100)
    mem.set("P", 0, 10000)
    mem.set("M", 0, 100)
    assert [mem.get(k, 0) for k in "SAPM"] == [100, 100, 10000, 100]


def test_6_2_s_range_keeps_sign(mem: Memory) -> None:
    mem.set("S", 13, 150)          # 6.2 "S13.3=150"
    mem.set("S", 1, -32767)
    assert mem.get("S", 1) == -32767
    mem.set("S", 1, 32767)
    refused(mem, "S", 1, 32768)
    refused(mem, "S", 1, -32768)


def test_6_2_a_negative_is_absolute_zero_refused(mem: Memory) -> None:
    mem.set("A", 6, 100)           # 6.2 "A6.3=100"
    mem.set("A", 2, -250)
    assert mem.get("A", 2) == 250
    mem.set("A", 2, 32767)
    mem.set("A", 3, -32767)
    assert mem.get("A", 3) == 32767
    refused(mem, "A", 2, 0)
    refused(mem, "A", 2, 32768)
    refused(mem, "A", 2, -32768)


def test_m_t_ranges(mem: Memory) -> None:
    mem.set("M", 2, 80)            # 6.2 "M2.3=80"
    mem.set("M", 0, 0)
    refused(mem, "M", 2, 101)
    refused(mem, "M", 2, -1)
    mem.set("T", 2, 500)           # 6.2 "T2.1=500"
    mem.set("T", 1, 32767)
    refused(mem, "T", 1, 32768)
    refused(mem, "T", 1, -1)


def test_p_range_follows_k37(mem: Memory) -> None:
    assert mem.k37 == 3            # 1000 ppr: max position 42,949,672
    mem.set("P", 1, 42_949_672)
    mem.set("P", 1, -42_949_672)
    refused(mem, "P", 1, 42_949_673)
    refused(mem, "P", 1, -42_949_673)
    mem.set("P", 0, 1_000_000_000)  # 2.1.1 "endless position"
    assert mem.get("P", 0) == 1_000_000_000
    refused(mem, "P", 1, -1_000_000_000)
    mem.set_k37(8)                 # 25000 ppr: 999,999,999
    mem.set("P", 1, 999_999_999)
    refused(mem, "P", 1, 1_000_000_001)
    with pytest.raises(OutOfRangeError):
        mem.set_k37(9)


def test_n_r_v_h_ranges(mem: Memory) -> None:
    for kind in "NR":
        mem.set(kind, 1, 1_000_000_000)
        mem.set(kind, 1, -1_000_000_000)
        refused(mem, kind, 1, 1_000_000_001)
    mem.set("V", 2, 12345678)      # 2.2.1 "V2.1=12345678"
    assert mem.get("V", 2) == VNumber(12345678)
    mem.set("V", 2, -1_000_000_000)
    refused(mem, "V", 2, 1_000_000_001)
    mem.set("H", 0, 32767)
    refused(mem, "H", 0, 32768)
    refused(mem, "H", 0, -1)


def test_memory_numbers_cm2(mem: Memory) -> None:
    for kind, top in zip("PSAMTVNRH", (200, 15, 8, 8, 8, 15, 200, 200, 0)):
        assert mem.limit(kind) == top
        mem.get(kind, 0)
        mem.get(kind, top)
        with pytest.raises(NoSuchRegisterError) as info:
            mem.get(kind, top + 1)
        assert isinstance(info.value, IndexError)
        assert info.value.motor_line(1) == "error00.1: Out Of Range!!"
        with pytest.raises(NoSuchRegisterError):
            mem.set(kind, -1, 1)


def test_memory_numbers_rt3() -> None:
    mem = Memory(RT3)
    for kind, top in zip("PSATVMRN", (25, 15, 7, 7, 15, 7, 25, 25)):
        assert mem.limit(kind) == top
        with pytest.raises(NoSuchRegisterError):
            mem.set(kind, top + 1, 1)


def test_kind_is_case_insensitive_and_checked(mem: Memory) -> None:
    mem.set("p", 3, 5)
    assert mem.get("P", 3) == 5
    with pytest.raises(ValueError):
        mem.get("Q", 1)


def test_factory_values(mem: Memory) -> None:
    assert mem.get("P", 1) == 0 and mem.get("S", 1) == 10 and mem.get("A", 1) == 100
    assert mem.get("M", 1) == 100 and mem.get("T", 1) == 0
    assert mem.get("V", 1) == VNumber(0) and mem.get("H", 0) == 0


# -- V values --------------------------------------------------------------------

def test_6_2_v_examples(mem: Memory) -> None:
    mem.set("V", 1, 1234)
    mem.set("V", 3, "abcd")        # 2.2.1 'V3.1="abcd"'
    mem.set("V", 4, "Px")          # 2.2.1 'V4.1="Px"'
    assert mem.get("V", 1) == VNumber(1234)
    assert mem.get("V", 3) == VString("abcd")
    assert mem.get("V", 4) == VState("Px")


def test_v_state_names_case_insensitive_with_aliases(mem: Memory) -> None:
    cases = {"px": "Px", "IX": "Ix", "uX": "Ux", "pe": "Pe", "ADIN": "ADIN", "AIN": "ADIN",
             "ain4": "ADIN", "PT": "PT", "Pt": "PT", "st": "ST", "CT": "CT", "Ecnt": "CT",
             "SX": "Sx"}
    for text, name in cases.items():
        mem.set("V", 5, text)
        assert mem.get("V", 5) == VState(name), text


def test_v_states_depend_on_firmware() -> None:
    assert parse_v_text("Fx", CM2.states) == VString("Fx")
    assert parse_v_text("Fx", RT3.states) == VState("Fx")
    assert parse_v_text("cx", RT3.states) == VState("Cx")
    assert parse_v_text("Dx", RT3.states) == VState("Dx")
    assert VState("Dx").write_only and not VState("Px").write_only
    assert state_name("Ecnt", CM2.states) == "CT"
    assert state_name("what") is None
    mem = Memory(CM2)
    with pytest.raises(OutOfRangeError):
        mem.set("V", 1, VState("Dx"))
    Memory(CM1).set("V", 1, VState("Dx"))


def test_v_strings_up_to_four_one_byte_characters(mem: Memory) -> None:
    mem.set("V", 1, "What")        # RT3 1.3 'V1="What"'
    mem.set("V", 2, "A")
    for bad in ("abcde", "", 'a"b', "é", "a\tb"):
        refused(mem, "V", 1, bad)
    assert mem.get("V", 1) == VString("What")


def test_v_rejects_other_types(mem: Memory) -> None:
    for bad in (1.5, None, True, [1]):
        refused(mem, "V", 1, bad)
    refused(mem, "P", 1, "1")
    refused(mem, "P", 1, 2.0)


def test_memory_numbers_and_kinds_of_other_types_are_refused(mem: Memory) -> None:
    """What the memory checks at run time it checks compiled too (coolmuscle/_accel.py):
    a bool or a float is not a memory number, a value or an allocation count."""
    mem.set("P", 1, 7)
    for bad_index in (True, 1.0, "1", None):
        with pytest.raises(NoSuchRegisterError):
            mem.get("P", bad_index)  # type: ignore[arg-type]
        with pytest.raises(NoSuchRegisterError):
            mem.set("P", bad_index, 5)
        with pytest.raises(NoSuchRegisterError):
            mem.number("P", bad_index)
    assert mem.get("P", 1) == 7
    for bad in (True, 2.0, None):
        with pytest.raises(OutOfRangeError):
            mem.set_v_number(1, bad)
        with pytest.raises(OutOfRangeError):
            mem.normalise("S", bad)
    assert mem.get("V", 1) == VNumber(0)
    for bad_count in (True, 300.0):
        with pytest.raises(OutOfRangeError):
            mem.allocate("P", bad_count)
    for bad_kind in (None, 1):
        with pytest.raises(ValueError):
            mem.get(bad_kind, 1)  # type: ignore[call-overload]


def test_v_values_pickle_and_stay_frozen() -> None:
    """Compiled too (coolmuscle/_accel.py): a V value pickles by its field, as the
    frozen dataclass of the sources does."""
    for value in (VNumber(-5), VString("ab"), VState("Px")):
        assert pickle.loads(pickle.dumps(value)) == value
        with pytest.raises(dataclasses.FrozenInstanceError):
            value.__setattr__(dataclasses.fields(value)[0].name, 1)


# -- allocation (2.1.2) ------------------------------------------------------------

def test_2_1_2_allocation_example(mem: Memory) -> None:
    mem.allocate("P", 300)         # "\P300"
    mem.allocate("N", 200)         # "\N200"
    assert mem.allocation == {"P": 300, "N": 200, "R": 100}
    assert (mem.limit("P"), mem.limit("N"), mem.limit("R")) == (300, 200, 100)
    mem.set("P", 300, 1)
    with pytest.raises(NoSuchRegisterError):
        mem.set("R", 101, 1)


def test_2_1_2_all_to_p_leaves_n_and_r_zero(mem: Memory) -> None:
    mem.allocate("P", 600)
    assert mem.allocation == {"P": 600, "N": 0, "R": 0}
    mem.set("P", 600, 5)
    mem.set("N", 0, 5)             # direct-mode data stays
    with pytest.raises(NoSuchRegisterError):
        mem.get("N", 1)


def test_allocation_p_first_n_shrinks_to_rest(mem: Memory) -> None:
    mem.allocate("P", 500)
    assert mem.allocation == {"P": 500, "N": 100, "R": 0}
    with pytest.raises(OutOfRangeError):
        mem.allocate("N", 101)
    mem.allocate("N", 0)
    assert mem.allocation == {"P": 500, "N": 0, "R": 100}
    for bad in (601, -1):
        with pytest.raises(OutOfRangeError):
            mem.allocate("P", bad)
    with pytest.raises(OutOfRangeError):
        mem.allocate("R", 10)
    assert mem.allocation == {"P": 500, "N": 0, "R": 100}


def test_allocation_keeps_data_that_fits_and_drops_the_rest(mem: Memory) -> None:
    mem.set("P", 5, 123)
    mem.set("N", 10, 7)
    mem.set("R", 150, 9)
    mem.set("R", 0, 4)
    mem.allocate("P", 300)
    mem.allocate("N", 200)
    assert mem.get("P", 5) == 123 and mem.get("N", 10) == 7 and mem.get("R", 0) == 4
    mem.allocate("P", 100)
    mem.allocate("N", 100)         # R back to 400: R150 is new again
    assert mem.get("R", 150) == 0


def test_allocation_only_r_type() -> None:
    for mem in (Memory(CM2.with_(motor_type="C")), Memory(RT3), Memory(CM1)):
        with pytest.raises(OutOfRangeError):
            mem.allocate("P", 300)


# -- serialisation -----------------------------------------------------------------

def test_to_dict_from_dict_round_trip(mem: Memory) -> None:
    mem.allocate("P", 400)
    mem.set("P", 400, -77)
    mem.set("V", 1, "Px")
    mem.set("V", 2, "ab")
    mem.set("V", 3, -5)
    mem.set("A", 8, 7)
    data = json.loads(json.dumps(mem.to_dict()))
    back = Memory.from_dict(CM2, data)
    assert back.to_dict() == mem.to_dict()
    assert back.get("V", 1) == VState("Px") and back.allocation == mem.allocation


def test_from_dict_checks_values(mem: Memory) -> None:
    data = mem.to_dict()
    data["A"][1] = 0
    with pytest.raises(ValueError):
        Memory.from_dict(CM2, data)
    with pytest.raises(ValueError):
        Memory.from_dict(RT3, mem.to_dict())          # wrong register counts
    with pytest.raises(ValueError):
        Memory.from_dict(CM2, {"alloc": {"P": 1}})
    data = mem.to_dict()
    data["V"][1] = {"x": 1}
    with pytest.raises(ValueError):
        Memory.from_dict(CM2, data)


def test_from_dict_uses_k37_for_p(mem: Memory) -> None:
    mem.set_k37(8)
    mem.set("P", 1, 500_000_000)
    with pytest.raises(ValueError):
        Memory.from_dict(CM2, mem.to_dict())           # K37=3 default
    assert Memory.from_dict(CM2, mem.to_dict(), k37=8).get("P", 1) == 500_000_000
