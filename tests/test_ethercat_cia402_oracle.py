"""The bridge's CiA402 logic against an independent oracle: python ``canopen``'s
CiA402 tables (``canopen.profiles.p402``: State402, OperationMode, Homing).
An alarm is a fault of an enabled motor (Switched on, Operation enabled: the table of
part 1, 6.1.1 transition 13); in State A it shows in bits 14/15 and stays latched
until the next Switched on enables the motor.

ethercat-bridge-users-guide.txt 6.1.1-6.1.3 (states, controlword, statusword), 6.2
(6502h, 6061h), 6.4.2 (homing bits 10, 12, 13).  canopen's tables are what a
CANopen/CoE master uses to drive a CiA402 servo; the manual differs from them in two
documented places, checked here as the manual says: quick stop is ignored (6.1.1
note), and "switch on & enable operation" (0Fh) from Ready to switch on goes to
Operation enabled (6.1.2, transitions 3 + 4; canopen has no such entry).
"""

from __future__ import annotations

from pathlib import Path

from canopen.profiles.p402 import Homing, OperationMode, State402
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ethercat_drive_support import Bench

COMMANDS = sorted(State402.CW_CODE_COMMANDS)          # 0x80, 0x00, 0x06, 0x07, 0x0F, 0x02
STOPPERS = Path(__file__).parent / "data" / "ethercat_stoppers.toml"


def state_of(statusword: int) -> str:
    """canopen's reading of a statusword (State402.SW_MASK)."""
    for name, (mask, value) in State402.SW_MASK.items():
        if statusword & mask == value:
            return name
    return "UNKNOWN"


def oracle(state: str, cw: int, previous: int) -> str:
    """The state canopen's transition table says ``cw`` leads to (manual exceptions noted)."""
    code = cw & 0x8F
    if code == State402.CW_QUICK_STOP:
        return state                                    # 6.1.1: ignored
    if state == "READY TO SWITCH ON" and code == State402.CW_OPERATION_ENABLED:
        return "OPERATION ENABLED"                      # 6.1.2: 3 + 4
    if code & 0x80 and previous & 0x80:
        return state                                    # fault reset is the 0 -> 1 edge
    for (frm, to), word in State402.TRANSITIONTABLE.items():
        if frm == state and word == (0x80 if code & 0x80 else code):
            return to
    return state


steps = st.lists(st.one_of(
    st.tuples(st.sampled_from(COMMANDS), st.integers(0, 7)),   # command, bits 4-6 (csp: N/A)
    st.just(("alarm", 0))), min_size=1, max_size=25)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(steps)
def test_6_1_controlword_statusword_agree_with_canopen_state402(sequence):
    b = Bench("EB02")
    assert state_of(b.status(1)) == "SWITCH ON DISABLED"
    previous = 0
    for command, extra in sequence:
        state = state_of(b.status(1))
        if command == "alarm":                          # 13: an alarm of an enabled motor
            b.chain.inject_fault(1, "over_current")
            b.cycles(1)
            enabled = state in ("SWITCHED ON", "OPERATION ENABLED")
            assert state_of(b.status(1)) == ("FAULT REACTION ACTIVE" if enabled else state)
            b.cycles(1)
            assert state_of(b.status(1)) == ("FAULT" if enabled else state)
            assert b.status(1) & 0xC000 == 0xC000       # 6.1.3 bits 14, 15: error, free
            continue
        cw = command | extra << 4
        b.pdo(1, cw, b.position(1))
        b.cycles(1)
        expected = oracle(state, cw, previous)
        assert state_of(b.status(1)) == expected, (hex(cw), state)
        previous = cw
        enabled = b.chain.snapshot(1).enabled
        if expected in ("SWITCHED ON", "OPERATION ENABLED") and state != expected:
            assert enabled                              # state B / C: motor enable
        if expected in ("SWITCH ON DISABLED", "READY TO SWITCH ON") and \
                state in ("SWITCHED ON", "OPERATION ENABLED"):
            assert not enabled                          # back to state A: motor free
        assert b.status(1) & 0x0200                     # remote, always


def test_6_2_supported_modes_and_display_agree_with_canopen_operationmode():
    b = Bench("EB02")
    supported = b.read(0x6502)
    names = {n for n, bit in OperationMode.SUPPORTED.items() if bit and supported & bit}
    assert names == {"HOMING", "CYCLIC SYNCHRONOUS POSITION"}
    assert OperationMode.CODE2NAME[b.read(0x6061)] == "CYCLIC SYNCHRONOUS POSITION"
    b.switch_mode(OperationMode.HOMING)
    assert OperationMode.CODE2NAME[b.read(0x6061)] == "HOMING"


def homing_state(statusword: int) -> str:
    for name, (mask, value) in Homing.STATES.items():
        if statusword & mask == value:
            return name
    return "UNKNOWN"


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from([1, 2]), st.integers(30, 80))
def test_6_4_2_homing_bits_agree_with_canopen_homing_states(method, speed):
    b = Bench("EB02", machine=STOPPERS)
    b.switch_mode(OperationMode.HOMING)
    b.enable((1,))
    assert homing_state(b.status(1)) == "INTERRUPTED"   # not started
    b.write(0x6098, 0, method)
    b.write(0x6099, 2, speed)
    b.cycles(100)
    b.pdo(1, 0x0F | Homing.CW_START)
    b.cycles(3)
    assert homing_state(b.status(1)) == "IN PROGRESS"
    b.until(lambda: homing_state(b.status(1)) != "IN PROGRESS", 30000)
    assert homing_state(b.status(1)) == "TARGET REACHED"
    assert b.position(1) == 0
