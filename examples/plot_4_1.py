"""Plots of the cml-users-guide.txt 4.1 motion examples (the images of docs/plots.md).

Run: ``PYTHONPATH=src python examples/plot_4_1.py [OUT_DIR]`` (default docs/images).

The manual's examples are program banks whose data table was lost with its figures;
the values below are chosen to show each motion clearly.  Until program banks are on
main the bank's lines are played through the Python API: each line starts when the
previous one is in position, as a bank does (2.2.2).  Output 1 is the in-position
signal in merge motion (K34=6, K73=30 ms), output 2 the in-position signal (K34=1).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable

from coolmuscle.chain import Chain
from coolmuscle.motor.motor import Motor
from coolmuscle.sim.kernel import seconds

Line = Callable[[Motor], None]


def _chain() -> tuple[Chain, Motor]:
    chain = Chain()
    chain.set_param(1, 34, 16)            # output 2: in position, output 1: merge pulse
    chain.set_param(1, 73, 30)
    chain.record()
    return chain, chain.motors[1]


def _bank(chain: Chain, motor: Motor, lines: list[Line], until: float) -> None:
    """Run ``lines`` one after the other, each when the previous one is in position."""
    pending = list(lines)

    def step() -> None:
        if pending:
            pending.pop(0)(motor)

    def on_event(event: object) -> None:
        if getattr(event, "kind", "") == "status" and getattr(event, "value", 0) == 8:
            chain.kernel.call_soon(step)

    chain.subscribe(on_event)
    step()
    chain.kernel.run(until=seconds(until))


def basic_ptp(out: Path) -> Path:
    """4.1.1: S1, A1, P1 / P2 / S2, P3: one motion a line, data kept until changed."""
    chain, motor = _chain()
    s1, s2 = motor.limits(50, 100), motor.limits(100, 100)
    _bank(chain, motor, [lambda m: m.move_to([(4000.0, s1)]),
                         lambda m: m.move_to([(8000.0, s1)]),
                         lambda m: m.move_to([(0.0, s2)])], until=3.2)
    return chain.plot(out / "4.1.1-basic-ptp.png",
                      title="4.1.1 basic PTP: S1 A1 P1 / P2 / S2 P3")


def merge(out: Path) -> Path:
    """4.1.2: S1, A1, P1, S2, P2, P3 in one line: no stop at P1 and P2."""
    chain, motor = _chain()
    s1, s2 = motor.limits(50, 100), motor.limits(100, 100)
    _bank(chain, motor, [lambda m: m.move_to([(3000.0, s1), (8000.0, s2), (12000.0, s2)])],
          until=2.0)
    return chain.plot(out / "4.1.2-merge.png",
                      title="4.1.2 merge motion: S1 A1 P1, S2 P2, P3 (pulses at the passing points)")


def merge_reversal(out: Path) -> Path:
    """4.1.2: a merge line whose direction turns over stops there, then goes on."""
    chain, motor = _chain()
    lim = motor.limits(80, 100)
    _bank(chain, motor, [lambda m: m.move_to([(3000.0, lim), (6000.0, lim), (1000.0, lim)])],
          until=2.2)
    return chain.plot(out / "4.1.2-merge-reversal.png",
                      title="4.1.2 merge motion removed where the direction turns over")


def accel_decel(out: Path) -> Path:
    """4.1.3: S1, A1, P1, A2, P2: slow acceleration, quick deceleration."""
    chain, motor = _chain()
    first = motor.limits(100, 30)
    second = motor.limits(100, 30, decel_a=300)
    _bank(chain, motor, [lambda m: m.move_to([(6000.0, first), (15000.0, second)])],
          until=2.2)
    return chain.plot(out / "4.1.3-accel-decel.png",
                      title="4.1.3 different acceleration and deceleration: S1 A1 P1, A2 P2")


def main(argv: list[str]) -> int:
    out = Path(argv[1]) if len(argv) > 1 else Path(__file__).parent.parent / "docs" / "images"
    out.mkdir(parents=True, exist_ok=True)
    for make in (basic_ptp, merge, merge_reversal, accel_decel):
        print(make(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
