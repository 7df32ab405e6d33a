"""Homing (hm, ethercat-bridge-users-guide.txt 6.4, Appendix 4) and the origin search
behind it (CMD mode F307h, Appendix 1.1).

The motor's own origin search does the work (cml-users-guide.txt 5.3): the bridge
sets its K parameters from the objects and sends ``|``.  :func:`homing_params`
maps 6098h (1 stopper CW, 2 stopper CCW, 3 switch CW, 4 switch CCW), 6099h.1/.2
(K42 for the switch / stopper search), 609Ah (K43) and 607Ch (K48) to K values;
:class:`OriginWatch` follows one search through the device API's cyclic state
(``CyclicState.origin_search`` / ``origin_done``) to its end: attained, or an
error (an alarm, the search stopped without its origin, or :data:`TIMEOUT_NS`).
"""

from __future__ import annotations

from typing import Final

from ....device import CyclicState, Device
from ....motor.status import ALARM_BITS

STOPPER_CW: Final = 1
STOPPER_CCW: Final = 2
SWITCH_CW: Final = 3
SWITCH_CCW: Final = 4
METHODS: Final = (STOPPER_CW, STOPPER_CCW, SWITCH_CW, SWITCH_CCW)

#: No time limit in the manual for "Origin Search Time Out" (7.1.3 F9xxh): chosen.
TIMEOUT_NS: Final = 60_000_000_000

IDLE: Final = "idle"
RUNNING: Final = "running"
ATTAINED: Final = "attained"
ERROR: Final = "error"
INTERRUPTED: Final = "interrupted"

#: 6.4.2 / CiA402 statusword bits 10 (target reached), 12 (attained), 13 (error).
STATUS_BITS: Final = {IDLE: 0x0400, RUNNING: 0x0000, ATTAINED: 0x1400, ERROR: 0x2400,
                      INTERRUPTED: 0x0400}


def homing_params(method: int, k45: int, k46: int, switch_speed: int,
                  stopper_speed: int) -> dict[int, int]:
    """The K42, K45, K46 values for 6098h ``method`` (the other digits kept).

    K45 ones digit: 0/2 CW, 1/3 CCW (2/3 reverse coordinates, kept); K46: 0 stopper,
    2 sensor, the power-up bit (odd) and CM1's 16+ kept.
    """
    stopper = method in (STOPPER_CW, STOPPER_CCW)
    ccw = method in (STOPPER_CCW, SWITCH_CCW)
    ones = k45 % 10
    ones = (2 if ones >= 2 else 0) + (1 if ccw else 0)
    keep = k46 - (k46 % 16) + (k46 % 2)          # CM1 16..19 and the power-up bit
    return {42: stopper_speed if stopper else switch_speed,
            45: k45 - k45 % 10 + ones,
            46: keep + (0 if stopper else 2)}


class OriginWatch:
    """One origin search of one motor, from ``|`` to its end."""

    def __init__(self, device: Device, motor: int) -> None:
        self.device = device
        self.motor = motor
        self.phase = IDLE
        self._started = 0

    @property
    def running(self) -> bool:
        return self.phase == RUNNING

    def start(self, now: int) -> None:
        self.device.execute(f"|.{self.motor}", origin="api")
        self._started = now
        self.phase = RUNNING

    def abort(self, phase: str = INTERRUPTED) -> None:
        """Stop the search (``]1.n``, pause this motor)."""
        if self.phase == RUNNING:
            self.device.execute(f"]1.{self.motor}", origin="api")
            self.phase = phase

    def update(self, snap: CyclicState, now: int) -> str:
        """Follow the search on this cycle's cyclic state; the phase after it."""
        if self.phase != RUNNING or now == self._started:   # ``snap`` is from before ``|``
            return self.phase
        searching = snap.origin_search
        if snap.status & ALARM_BITS:
            self.phase = ERROR
        elif not searching:
            self.phase = ATTAINED if snap.origin_done else ERROR
        elif now - self._started > TIMEOUT_NS:
            self.abort(ERROR)
        return self.phase

    def reset(self) -> None:
        self.phase = IDLE
