"""The ``chain`` door's wire faults: a motor powered off and on again, a broken link.

A chained motor relays what passes between the host and the motors beyond it (ID n's
COM1 is wired to ID n+1's COM0, cml-users-guide.txt 1.1); the manual does not say what
the others see when one of them is off or a link is broken, so the choices are in
docs/fidelity.md "Wire faults":

* **powered off** (``power_off``, motor N): motor N answers nothing and relays nothing,
  so every ID from N on is cut off from the host (their lines are lost, their reports
  never arrive).  Motor N itself stops: its banks and ladder end, the servo lets go
  and the shaft coasts.  When the fault ends it powers up as a motor does: with what
  ``$`` saved (registers, banks; the store's snapshot) and its K parameters, which
  persist by themselves when written (ch. 3); unsaved registers and banks are lost, the
  position counts from where the shaft stands (as at power-up), alarms and the
  emergency stop are cleared, then the power-up rules run (K68, K46, K62).
* **broken link** (``link_break``, motor N): the link from N to N+1 carries nothing;
  IDs from N+1 on are cut off but keep running what they run.

:func:`coolmuscle.device.wire.chain.cut_from` is the first ID the host cannot reach.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from ..motor.state.memory import Memory

if TYPE_CHECKING:
    from ..motor.motor import Motor

__all__ = ["power_off", "power_on_again"]


def power_off(motor: Motor) -> None:
    """Motor off: its banks and ladders end, the servo lets go (the shaft coasts)."""
    motor.program.terminate()
    motor.ladder.stop()
    motor.logic_motion.stop()
    motor.pending_baud = None
    motor.free()


def power_on_again(motor: Motor, saved: Mapping[str, Any] | None) -> None:
    """Power up after :func:`power_off` with ``saved`` (what ``$`` stored: its
    ``memory`` and ``banks``; ``None``: nothing was ever saved).  The K parameters stay
    as they are: they persist by themselves when written (ch. 3)."""
    firmware, k37 = motor.firmware, motor.k(37)
    memory = saved.get("memory") if saved else None
    motor.memory = Memory(firmware, k37=k37)
    if isinstance(memory, dict):
        try:
            motor.memory = Memory.from_dict(firmware, memory, k37=k37)
        except ValueError:           # what no longer fits is not restored (as at start)
            motor.memory = Memory(firmware, k37=k37)
    motor.banks.clear(False)
    motor.banks.clear(True)
    banks = saved.get("banks") if saved else None
    if isinstance(banks, dict):
        motor.banks.load_dict(banks)
    general = motor.io.general
    general[:] = [False] * len(general)    # the general outputs start off
    motor.estopped = False
    motor.origin_done = False
    motor.enable()                   # clears a latched alarm; K68 may free it again
    motor.set_origin()               # the count starts where the shaft stands
    motor.power_on()
