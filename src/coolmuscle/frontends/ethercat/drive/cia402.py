"""The CiA402 state machine of one axis as a pure table (ethercat-bridge-users-guide.txt 6.1).

No I/O, no clock: :func:`step` maps (state, controlword, previous controlword, motor
alarm) to the next state and the PDS transition number of the 6.1.1 diagram, and
:func:`statusword` gives bits 0-6 and 9 of 6.1.3 for a state.  What a transition
does to the Cool Muscle (state A motor free, B motor enable, C ready for operation)
is :data:`COOL_MUSCLE_STATE`; the axis (:mod:`.axis`) acts on it.

Quick stop is not supported (6.1.1 note "it ignores Quick stop active command"): a
quick stop controlword leaves the state as it is.  Bit 5 of the statusword (Qs,
"-" in the 6.1.3 table) reads 1, "no quick stop active", in the states where
CiA402 defines it, so a standard master does not mistake Operation enabled for
Quick stop active (docs/fidelity.md "EtherCAT drive").
"""

from __future__ import annotations

from enum import IntEnum


class State(IntEnum):
    """The CiA402 PDS states of 6.1.1."""

    NOT_READY_TO_SWITCH_ON = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    FAULT_REACTION_ACTIVE = 5
    FAULT = 6


#: 6.1.1 "Reference (Cool Muscle State)": A motor free, B motor enable, C ready.
COOL_MUSCLE_STATE = {
    State.NOT_READY_TO_SWITCH_ON: "A", State.SWITCH_ON_DISABLED: "A",
    State.READY_TO_SWITCH_ON: "A", State.SWITCHED_ON: "B",
    State.OPERATION_ENABLED: "C", State.FAULT_REACTION_ACTIVE: "C", State.FAULT: "A",
}

#: 6.1.3 bits 0-6 (Rtso, So, Oe, F, Ve, Qs, Sod) per state.
_STATUS_BITS = {
    State.NOT_READY_TO_SWITCH_ON: 0x0000,
    State.SWITCH_ON_DISABLED: 0x0040,
    State.READY_TO_SWITCH_ON: 0x0031,
    State.SWITCHED_ON: 0x0033,
    State.OPERATION_ENABLED: 0x0037,
    State.FAULT_REACTION_ACTIVE: 0x000F,
    State.FAULT: 0x0008,
}

REMOTE = 0x0200             # 6.1.3 bit 9 "Remote: 1 fixed"
FAULT_RESET = 0x0080        # 6.1.2 bit 7


def command(controlword: int) -> str:
    """The 6.1.2 command a controlword encodes (bits 0-3 and 7)."""
    cw = controlword & 0x008F
    if cw & FAULT_RESET:
        return "fault reset"
    if not cw & 0x02:
        return "disable voltage"                  # x x 0 x
    if not cw & 0x04:
        return "quick stop"                       # x 0 1 x (N/A, ignored)
    if not cw & 0x01:
        return "shutdown"                         # x 1 1 0
    return "enable operation" if cw & 0x08 else "switch on"


#: (state, command) -> (next state, PDS transition number of the 6.1.1 diagram).
_TABLE: dict[tuple[State, str], tuple[State, int]] = {
    (State.SWITCH_ON_DISABLED, "shutdown"): (State.READY_TO_SWITCH_ON, 2),
    (State.READY_TO_SWITCH_ON, "switch on"): (State.SWITCHED_ON, 3),
    (State.READY_TO_SWITCH_ON, "enable operation"): (State.OPERATION_ENABLED, 34),  # 3 + 4
    (State.READY_TO_SWITCH_ON, "disable voltage"): (State.SWITCH_ON_DISABLED, 7),
    (State.SWITCHED_ON, "enable operation"): (State.OPERATION_ENABLED, 4),
    (State.SWITCHED_ON, "shutdown"): (State.READY_TO_SWITCH_ON, 6),
    (State.SWITCHED_ON, "disable voltage"): (State.SWITCH_ON_DISABLED, 10),
    (State.OPERATION_ENABLED, "switch on"): (State.SWITCHED_ON, 5),
    (State.OPERATION_ENABLED, "shutdown"): (State.READY_TO_SWITCH_ON, 8),
    (State.OPERATION_ENABLED, "disable voltage"): (State.SWITCH_ON_DISABLED, 9),
}


def step(state: State, controlword: int, previous: int, alarm: bool) -> tuple[State, int]:
    """The next state and its transition number (0: none) for one bridge cycle.

    ``alarm``: the motor reports an alarm (6.1.1 transition 13 "Error occurs").
    Fault reaction active lasts one cycle (14); fault reset is the 0 -> 1 edge of
    bit 7 (15).
    """
    if state is State.NOT_READY_TO_SWITCH_ON:
        return State.SWITCH_ON_DISABLED, 1
    if state is State.FAULT_REACTION_ACTIVE:
        return State.FAULT, 14
    if state is State.FAULT:
        if controlword & FAULT_RESET and not previous & FAULT_RESET:
            return State.SWITCH_ON_DISABLED, 15
        return state, 0
    if alarm:
        return State.FAULT_REACTION_ACTIVE, 13
    found = _TABLE.get((state, command(controlword)))
    return found if found is not None else (state, 0)


def statusword(state: State) -> int:
    """Bits 0-6 and 9 of 6.1.3 for ``state`` (the mode adds bits 10-15)."""
    return _STATUS_BITS[state] | REMOTE


def decode(word: int) -> State | None:
    """The state a statusword shows (the 6.1.3 table read backwards), or ``None``."""
    for state in (State.FAULT_REACTION_ACTIVE, State.FAULT, State.SWITCH_ON_DISABLED,
                  State.OPERATION_ENABLED, State.SWITCHED_ON, State.READY_TO_SWITCH_ON,
                  State.NOT_READY_TO_SWITCH_ON):
        if word & 0x4F == _STATUS_BITS[state] & 0x4F:
            return state
    return None
