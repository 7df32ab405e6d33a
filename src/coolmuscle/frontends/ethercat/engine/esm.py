"""The EtherCAT state machine as a pure table (ETG.1000.6 6.4.1).

No I/O, no clock: :func:`request` takes the current AL status, the value the master
wrote to AL control (0x0120) and a check for the transition, and returns the new
AL status and AL status code.

* Valid steps: INIT->PRE-OP, PRE-OP->SAFE-OP, SAFE-OP->OP (IP/PS/SO) and every
  step down (PI, SP, SI, OS, OP, OI).  Others (INIT->SAFE-OP, INIT->OP, PRE-OP->OP)
  answer 0011h "invalid requested state change"; a value that names no state
  answers 0012h; BOOT answers 0013h (no bootstrap state is offered).  The
  device stays where it is and sets the error indication (AL status bit 4).
* While the error indication is set, a request without the acknowledge bit (AL
  control bit 4) may only go down; a request with it clears the indication first.
* Total: any AL status and any AL control value give an outcome, never an exception.
  A current state that names no state (an AL status the firmware never writes) counts
  as INIT, the state in which nothing runs.
* :func:`fault` is a local error taking the device down (the SM watchdog in OP to
  SAFE-OP with 001Bh; a SyncManager the master changed in PRE-OP or above, ETG.1000.6
  as the slave stack checks it on the SM change event: to INIT with 0016h for a
  mailbox SyncManager, to PRE-OP with 001Dh / 001Eh for the process data ones).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

INIT, PREOP, BOOT, SAFEOP, OP = 1, 2, 3, 4, 8
NAMES = {INIT: "INIT", PREOP: "PRE-OP", BOOT: "BOOT", SAFEOP: "SAFE-OP", OP: "OP"}
ERROR_FLAG = 0x10
ACK = 0x10

# AL status codes (ETG.1000.6, AL status code register 0x0134).
NO_ERROR = 0x0000
UNSPECIFIED = 0x0001
INVALID_STATE_CHANGE = 0x0011
UNKNOWN_STATE = 0x0012
BOOT_NOT_SUPPORTED = 0x0013
INVALID_MAILBOX_CONFIG = 0x0016      # ETG.1000.6: 0016h on the way to PRE-OP (fidelity.md)
INVALID_SM_CONFIG = 0x0017
SM_WATCHDOG = 0x001B
INVALID_SM_TYPES = 0x001C
INVALID_OUTPUT_CONFIG = 0x001D
INVALID_INPUT_CONFIG = 0x001E
INVALID_WATCHDOG_CONFIG = 0x001F

_ORDER = {INIT: 0, PREOP: 1, SAFEOP: 2, OP: 3}
_UP = {(INIT, PREOP), (PREOP, SAFEOP), (SAFEOP, OP)}

#: check(current, requested) -> AL status code (0 = the transition may happen).
Check = Callable[[int, int], int]


@dataclass(frozen=True)
class Outcome:
    """The AL status after a request."""

    state: int
    error: bool
    code: int
    changed: bool

    @property
    def al_status(self) -> int:
        return self.state | (ERROR_FLAG if self.error else 0)


def request(al_status: int, al_code: int, control: int, check: Check) -> Outcome:
    """Apply the master's AL control value to the current AL status."""
    out = _request(al_status, al_code, control, check)
    if _known(al_status & 0x0F) != al_status & 0x0F:     # an unknown state left for INIT
        out = replace(out, changed=True, code=out.code if out.error else NO_ERROR)
    return out


def _request(al_status: int, al_code: int, control: int, check: Check) -> Outcome:
    state = _known(al_status & 0x0F)
    error = bool(al_status & ERROR_FLAG)
    wanted = control & 0x0F
    if error and control & ACK:
        error, al_code = False, NO_ERROR
    if wanted not in (INIT, PREOP, BOOT, SAFEOP, OP):
        return Outcome(state, True, UNKNOWN_STATE, False)
    if wanted == BOOT:
        return Outcome(state, True, BOOT_NOT_SUPPORTED, False)
    if error and _ORDER[wanted] >= _ORDER[state]:
        return Outcome(state, error, al_code, False)       # not acknowledged: stay
    if wanted == state:
        return Outcome(state, error, al_code, False)
    if _ORDER[wanted] > _ORDER[state] and (state, wanted) not in _UP:
        return Outcome(state, True, INVALID_STATE_CHANGE, False)
    code = check(state, wanted)
    if code:
        return Outcome(state, True, code, False)
    return Outcome(wanted, error, al_code if error else NO_ERROR, True)


def fault(al_status: int, to_state: int, code: int) -> Outcome:
    """A local error takes the device down to ``to_state`` (never up: below it, the
    device stays where it is) with the error indication and ``code``."""
    raw = al_status & 0x0F
    state = _known(raw)
    target = to_state if _ORDER[state] > _ORDER[_known(to_state)] else state
    return Outcome(target, True, code, target != raw)


def _known(state: int) -> int:
    """``state`` if it names a state the device can be in, else INIT."""
    return state if state in _ORDER else INIT
