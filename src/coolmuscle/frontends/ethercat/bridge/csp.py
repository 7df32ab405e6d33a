"""Cyclic synchronous position mode (ethercat-bridge-users-guide.txt 6.3, Appendix 5).

The target position 607Ah of every cycle goes to the motor through the device
API's ``target_stream`` (one target each 1 ms cycle, 6.3); the servo model follows
it with its own lag, a stepper (CM1) ramps to it over the cycle.  A target
beyond the maximum position of the motor's resolution (Appendix 5, K37) is held at
that maximum; the motor's own software limits (K58/K59) apply inside the model.
"""

from __future__ import annotations

from typing import Final

from ....device import Device, TargetStream
from ....motor.state.units import RESOLUTIONS
from .identity import CYCLE_NS

#: Appendix 5's maximum position by K37 (read at every cycle: a table of ints, not the
#: resolutions' objects).
_MAX_POSITION: Final = {k37: res.max_position for k37, res in RESOLUTIONS.items()}


def max_position(k37: int) -> int:
    """Appendix 5: the largest position the motor takes at resolution ``k37``."""
    return _MAX_POSITION.get(k37, 999_999_999)


def clamp(target: int, k37: int) -> int:
    """``target`` within +/- the Appendix 5 maximum."""
    top = max_position(k37)
    return max(-top, min(top, target))


class Follower:
    """The csp target stream of one axis: opened on Operation enabled, closed on leaving."""

    def __init__(self, device: Device, motor: int) -> None:
        self.device = device
        self.motor = motor
        self._stream: TargetStream | None = None
        self._last: int | None = None
        self.pushed = 0

    @property
    def active(self) -> bool:
        return self._stream is not None

    def start(self) -> None:
        if self._stream is None:
            self._stream = self.device.target_stream(self.motor, CYCLE_NS)
            self._last = None

    def push(self, target: int) -> None:
        """The cycle's target (an unchanged target is the same command: not sent again)."""
        if self._stream is not None and target != self._last:
            self._stream.push(target)
            self._last = target
            self.pushed += 1

    def stop(self) -> None:
        if self._stream is not None:
            self._stream.close()
            self._stream = None
            self._last = None
