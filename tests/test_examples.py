"""examples/: the manuals' sample programs, run with ``coolmuscle run`` on the model.

Every example runs without a failure; where the model already implements what the
example shows, the reply that proves it is checked too.  (The ``@`` interpolation of
4.4 belongs to the daisy-chain issue: those examples load and run their first line.)
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.client.program import load_program
from coolmuscle.tools.script.runner import run_script

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.cml"))

#: example -> a line the motor must have said (the result the manual describes)
PROVES = {
    "2.1-operation.cml": b"Px.1=10000\r\n",
    "2.2-program-bank.cml": b"Ux.1=8\r\n",
    "2.2.3-ladder-bank.cml": b"Px.1=10000\r\n",
    "4.1.3-accel-decel.cml": b"Px.1=10000\r\n",
    # 4.1.4 with its machine file (the object at 11000): the push completes
    "4.1.4-push-motion.cml": b"Ux.1=40\r\n",
    "origin-search.cml": b"Px.1=0\r\n",
    "4.3.2-two-axes.cml": b"Px.2=2000\r\n",
    "4.5.1-ladder-basic.cml": b"V1.1=100\r\n",
    "6.3-loop.cml": b"Px.1=2000\r\n",
    "rt3-1.2-registers.cml": b"A1.1=100\r\n",
    "rt3-7.2-analog-speed.cml": b"Sx.1=100\r\n",
    "rt3-7.3.1-torque-position.cml": b"Px.1=10000\r\n",
}


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_runs(path: Path) -> None:
    program = load_program(path)
    machine = re.search(r"^# coolmuscle:.*\bmachine=(\S+)", path.read_text(), re.M)
    chain = Chain(firmware=program.firmware or "cm2", motors=program.motors or 1,
                  machine=path.parent / machine.group(1) if machine else None)
    try:
        result = run_script(path, chain)
    finally:
        chain.close()
    assert result.ok, result.summary()
    received = b"".join(e.data for e in result.transcript if e.direction == "<")
    assert PROVES.get(path.name, b"") in received
    assert b"error" not in received


def test_every_file_an_example_names_exists() -> None:
    """Examples and machine files name other files (``coolmuscle run examples/X.cml``,
    ``machine=X.toml``): each one is in the checkout."""
    named = set()
    for path in (ROOT / "examples").iterdir():
        if path.suffix in (".cml", ".toml", ".py"):
            text = path.read_text(encoding="utf-8")
            named |= {ROOT / m for m in re.findall(r"\b(examples/[\w.-]+\.(?:cml|toml))", text)}
            named |= {path.parent / m for m in re.findall(r"machine=([\w.-]+\.toml)", text)}
    assert named and all(p.exists() for p in named), sorted(str(p) for p in named
                                                            if not p.exists())
