"""examples/: the manuals' sample programs run with ``coolmuscle run``.

Examples that define banks need the program/ladder bank model (another branch);
until it is on main only the examples without banks are run here (``check`` covers
every example, tests/test_check.py).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from coolmuscle.chain import Chain
from coolmuscle.client.program import load_program
from coolmuscle.script import run_script

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.cml"))
WITHOUT_BANKS = [p for p in EXAMPLES if not load_program(p).banks]


def test_some_examples_have_no_banks() -> None:
    assert {p.name for p in WITHOUT_BANKS} == {"2.1-operation.cml",
                                                "rt3-7.3.1-torque-position.cml"}


@pytest.mark.parametrize("path", WITHOUT_BANKS, ids=lambda p: p.name)
def test_example_runs(path: Path) -> None:
    program = load_program(path)
    chain = Chain(firmware=program.firmware or "cm2", motors=program.motors or 1)
    try:
        result = run_script(path, chain)
    finally:
        chain.close()
    assert result.ok, result.summary()
    received = [e.data for e in result.transcript if e.direction == "<"]
    assert b"Px.1=10000\r\n" in received
