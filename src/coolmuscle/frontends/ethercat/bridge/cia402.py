"""The CiA402 power drive state machine of one axis as a pure table (manual 6.1).

No I/O, no clock: :func:`next_state` takes the state, the controlword (6040h, 6.1.2),
the previous controlword (fault reset acts on the rising edge of bit 7) and whether
the motor has an alarm, and returns the next state.  An alarm while the motor is
enabled (Switched on, Operation enabled) is a fault; the latched alarm of a motor
in State A is cleared by the enable of the next Switched on (6.1.1 State C note 1),
so a fault reset needs no cleared alarm; :func:`statusword` gives 6041h
(6.1.3).  The Cool Muscle side of each state (6.1.1: State A motor free, B motor
enable, C ready for operation) is :func:`motor_state`.  Quick stop is not supported
(6.1.1 State C note 2): a quick stop command is ignored.
"""

from __future__ import annotations

import enum
from typing import Final


class State(enum.Enum):
    NOT_READY = "Not ready to switch on"
    SWITCH_ON_DISABLED = "Switch on disabled"
    READY = "Ready to switch on"
    SWITCHED_ON = "Switched on"
    OPERATION_ENABLED = "Operation enabled"
    FAULT_REACTION = "Fault reaction active"
    FAULT = "Fault"


#: 6.1.3 table A, bits 0-6 (quick stop bit 5 reads 1 = "not active": it never happens).
_BITS: Final = {State.NOT_READY: 0x0000, State.SWITCH_ON_DISABLED: 0x0040, State.READY: 0x0021,
                State.SWITCHED_ON: 0x0023, State.OPERATION_ENABLED: 0x0027,
                State.FAULT_REACTION: 0x000F, State.FAULT: 0x0008}

#: 6.1.1 "Reference (Cool Muscle State)".
_MOTOR: Final = {State.NOT_READY: "A", State.SWITCH_ON_DISABLED: "A", State.READY: "A",
                 State.SWITCHED_ON: "B", State.OPERATION_ENABLED: "C", State.FAULT_REACTION: "C",
                 State.FAULT: "A"}

REMOTE: Final = 0x0200            # bit 9: fixed 1
FOLLOWING: Final = 0x1000         # bit 12 in csp: follows the target position
MOTOR_ERROR: Final = 0x4000       # bit 14
MOTOR_FREE: Final = 0x8000        # bit 15


def motor_state(state: State) -> str:
    """Cool Muscle state A (motor free), B (motor enable) or C (ready) of a CiA402 state."""
    return _MOTOR[state]


def command(cw: int) -> str:
    """The 6.1.2 command a controlword carries (bits 7, 3, 2, 1, 0)."""
    if cw & 0x02 == 0:
        return "disable voltage"
    if cw & 0x04 == 0:
        return "quick stop"
    if cw & 0x01 == 0:
        return "shutdown"
    return "enable operation" if cw & 0x08 else "switch on"


def next_state(state: State, cw: int, previous_cw: int, alarm: bool) -> State:
    """One step of the 6.1.1 diagram (transitions 1-15)."""
    if state is State.NOT_READY:
        return State.SWITCH_ON_DISABLED                                   # 1
    if alarm and state in (State.SWITCHED_ON, State.OPERATION_ENABLED):
        return State.FAULT_REACTION    # 13: an alarm of the motor while enabled (B, C)
    if state is State.FAULT_REACTION:
        return State.FAULT                                                # 14
    if state is State.FAULT:
        if cw & 0x80 and not previous_cw & 0x80:
            return State.SWITCH_ON_DISABLED                               # 15
        return State.FAULT             # the alarm stays latched until Switched on (6.1.1)
    if cw & 0x80:
        return state                   # fault reset outside Fault: nothing (6.1.2)
    cmd = command(cw)
    if cmd == "quick stop":
        return state                   # not supported: ignored (6.1.1 note 2)
    if cmd == "disable voltage":
        return State.SWITCH_ON_DISABLED                                   # 7, 9, 10, 12
    if cmd == "shutdown":
        return State.READY                                                # 2, 6, 8
    if cmd == "switch on":
        if state is State.READY:
            return State.SWITCHED_ON                                      # 3
        if state is State.OPERATION_ENABLED:
            return State.SWITCHED_ON                                      # 5
        return state
    if state is State.READY:
        return State.OPERATION_ENABLED                                    # 3 + 4
    if state is State.SWITCHED_ON:
        return State.OPERATION_ENABLED                                    # 4
    return state


def statusword(state: State, *, csp: bool, alarm: bool, free: bool) -> int:
    """6041h: bits 0-6 of the state, remote, csp following, motor error, motor free."""
    # Operation enabled tested first, by identity: every cycle of a moving axis asks,
    # and a lookup in _BITS hashes the member in Python (Enum.__hash__).
    word = (0x0027 if state is State.OPERATION_ENABLED else _BITS[state]) | REMOTE
    if csp and state is State.OPERATION_ENABLED:
        word |= FOLLOWING
    if alarm:
        word |= MOTOR_ERROR
    if free:
        word |= MOTOR_FREE
    return word
