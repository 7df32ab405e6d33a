"""The station's host program: load the banks, run a pick-and-place cycle, report.

It speaks to the motor through coolmuscle's host library over any pyserial URL or an
open port: a real motor (``/dev/ttyUSB0``), a served simulator (``socket://...``) or a
virtual chain in a test (``cm_chain.port()``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from coolmuscle.client import connect

BANKS = Path(__file__).resolve().parents[1] / "banks" / "pick.cml"
PLACE = 6000


def load(port: Any, banks: Path = BANKS, timeout: float = 2.0) -> None:
    """Upload the bank set and verify it by readback."""
    with connect(port, timeout=timeout) as motor:
        motor.upload(banks)


def run_cycle(port: Any, timeout: float = 2.0, polls: int = 100) -> int:
    """Start program bank 1 and follow the carry: the farthest position reached (the
    place station when all goes well)."""
    with connect(port, timeout=timeout) as motor:
        motor.start_bank(1)
        farthest = 0
        for _ in range(polls):
            farthest = max(farthest, motor.get_position())
            if farthest >= PLACE - 10:
                break
            motor.poll(0.05)
        return farthest
