"""Helpers for the bank, ladder and I/O function tests: a chain driven line by line."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from coolmuscle.chain.daisy import Chain
from coolmuscle.device.api import Event
from coolmuscle.sim.kernel import seconds
from fixtures import new_chain


@dataclass
class Rig:
    """A chain, what it printed (time ns, text) and shortcuts to type and to wait."""

    chain: Chain
    printed: list[tuple[int, str]] = field(default_factory=list)

    @property
    def kernel(self) -> Any:
        return self.chain.kernel

    def motor(self, motor_id: int = 1) -> Any:
        return self.chain.motors[motor_id]

    def type(self, *lines: str) -> None:
        """Lines as typed on the host line (replies are recorded in ``printed``)."""
        for line in lines:
            self.chain.execute(line, origin="host")

    def wait(self, s: float) -> None:
        self.kernel.advance(seconds(s))

    def until(self, s: float) -> None:
        self.kernel.run(until=seconds(s))

    def texts(self, since: int = 0) -> list[str]:
        return [text for t, text in self.printed if t >= since]

    def times(self, text: str) -> list[int]:
        return [t for t, seen in self.printed if seen == text]

    def clear(self) -> None:
        self.printed.clear()


def rig(*lines: str, motors: int = 1, firmware: str = "cm2", k23: int = 25,
        **options: Any) -> Rig:
    """A fresh chain with K23 = ``k23`` (no echo, messages on) and ``lines`` typed."""
    chain = new_chain(motors, firmware, **options)
    result = Rig(chain)

    def listen(event: Event) -> None:
        if event.origin in ("host", "bank", "ladder", "motor"):
            result.printed.append((event.time, event.text))
    chain.subscribe(listen)
    result.type(f"K23.1={k23}")
    result.type(*lines)
    return result


def enters_window(trace: Any, motor_id: int, t: int, target: float, window: int = 5) -> bool:
    """Whether ``t`` is when the actual position comes within ``window`` (K55) of
    ``target``: inside at ``t``, outside 1 µs before (ch. 3 K55 in-position)."""
    inside = abs(trace.sample(motor_id, t).position - target) <= window + 1e-6
    before = abs(trace.sample(motor_id, t - 1000).position - target) > window
    return inside and before
