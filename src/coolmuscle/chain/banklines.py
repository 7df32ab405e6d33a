"""The chain's side of :mod:`coolmuscle.device.banklines`: observers on every motor's banks.

While somebody listens, each motor's program executor and its ladder and logic motion
runners hold an observer (:data:`coolmuscle.motor.programs.bankexec.LineObserver`)
that turns ``(bank, first, last)`` into a :class:`~coolmuscle.device.banklines.BankLine`
stamped with the kernel's time; when the last listener goes, the observers are taken
off again and the banks run as they do unobserved.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

from ..device.banklines import BankLine, BankLineListener

if TYPE_CHECKING:
    from ..motor.motor import Motor
    from ..sim.kernel import Kernel


class BankLineObservers:
    """The listeners of one chain and the observers they put on its motors."""

    def __init__(self, kernel: Kernel, motors: Mapping[int, Motor]) -> None:
        self.kernel = kernel
        self.motors = motors
        self.listeners: list[BankLineListener] = []

    def add(self, listener: BankLineListener) -> Callable[[], None]:
        """Start telling ``listener``; returns its remover."""
        self.listeners.append(listener)
        if len(self.listeners) == 1:
            self._install(True)

        def remove() -> None:
            if listener in self.listeners:
                self.listeners.remove(listener)
                if not self.listeners:
                    self._install(False)
        return remove

    def _install(self, on: bool) -> None:
        for motor in self.motors.values():
            motor.program.line_observer = self._observer(motor.id, False) if on else None
            motor.ladder.line_observer = self._observer(motor.id, True) if on else None
            motor.logic_motion.line_observer = self._observer(motor.id, True) if on else None

    def _observer(self, motor: int, ladder: bool) -> Callable[[int, int, int], None]:
        kernel, listeners = self.kernel, self.listeners

        def observed(bank: int, first: int, last: int) -> None:
            line = BankLine(kernel.now, motor, ladder, bank, first, last)
            for listener in list(listeners):
                listener(line)
        return observed
