"""One axis of the bridge as a CiA402 drive in csp, over the device API (manual 6.1, 6.3).

:class:`Drive` runs in the model's thread, once per bridge cycle: it steps the
:mod:`.cia402` table with the controlword of the output image, makes the motor
follow the state's Cool Muscle side (6.1.1: State A motor free, B motor enable,
through the CML commands ``).n`` / ``(.n``), and in Operation enabled with 6060h = 8
(csp) pushes each new target position (607Ah) into ``Device.target_stream``.  It
never touches motor internals.  A motor alarm (Ux 1, 2, 4, 64, 128; CML 6.6 ?99) is
a Fault; a fault reset (bit 7 rising) clears it through the enable the next
Switched on gives (6.1.1 State C note 1).
"""

from __future__ import annotations

import logging
from typing import Any

from . import cia402
from .cia402 import State

log = logging.getLogger(__name__)

#: Ux bits that are alarms (CML 6.6 ?99): position error, over speed, overload,
#: over current, temperature.
ALARM_MASK = 0x01 | 0x02 | 0x04 | 0x40 | 0x80
MODE_CSP = 8


class Drive:
    """The CiA402 side of motor ``axis`` (1..4)."""

    def __init__(self, device: Any, axis: int) -> None:
        self.device = device
        self.axis = axis
        self.state = State.NOT_READY
        self._previous_cw = 0
        self._stream: Any = None
        self._last_target: int | None = None

    def step(self, cw: int, target: int, mode: int, snapshot: Any, operational: bool) -> int:
        """One cycle: returns the statusword (6041h)."""
        alarm = bool(snapshot.status & ALARM_MASK)
        if not operational and self.state is State.OPERATION_ENABLED:
            cw = 0x0007                # the master is gone: disable operation, hold
        new = cia402.next_state(self.state, cw, self._previous_cw, alarm)
        self._previous_cw = cw
        if new is not self.state:
            self._enter(self.state, new, snapshot)
            self.state = new
        csp = mode == MODE_CSP
        if self.state is State.OPERATION_ENABLED and csp and operational:
            self._follow(target)
        free = not snapshot.enabled
        return cia402.statusword(self.state, csp=csp, alarm=alarm, free=free)

    def _enter(self, old: State, new: State, snapshot: Any) -> None:
        log.debug("ID%d %s -> %s", self.axis, old.value, new.value)
        if old is State.OPERATION_ENABLED:
            self._stop_following()
        before, after = cia402.motor_state(old), cia402.motor_state(new)
        if after == "A" and before in ("B", "C") and new is not State.FAULT:
            self._execute(f").{self.axis}")                  # motor free (6.1.1 A.2)
        elif after in ("B", "C") and before == "A":
            self._execute(f"(.{self.axis}")                  # motor enable (6.1.1 B)
        if new is State.OPERATION_ENABLED:
            self._last_target = None

    def _follow(self, target: int) -> None:
        if self._stream is None:
            self._stream = self.device.target_stream(self.axis)
        if target != self._last_target:
            self._stream.push(int(target))
            self._last_target = target

    def _stop_following(self) -> None:
        if self._stream is not None:
            self._stream.close()
            self._stream = None

    def _execute(self, line: str) -> None:
        try:
            self.device.execute(line, origin="fieldbus")
        except Exception:
            log.exception("ID%d: %s failed", self.axis, line)

    def close(self) -> None:
        self._stop_following()
