"""``coolmuscle enip eds`` and ``coolmuscle sim --enip`` (docs/enip.md)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from coolmuscle.frontends.enip.cm1.eds import generate
from coolmuscle.tools.cli.enip import optional_value_argv, parse_enip

SRC = Path(__file__).resolve().parents[1] / "src"


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "coolmuscle", *args], capture_output=True,
                          text=True, timeout=60, env={"PYTHONPATH": str(SRC), "PATH": ""})


def test_enip_eds_prints_the_generated_eds():
    out = _run("enip", "eds")
    assert out.returncode == 0 and out.stdout == generate()


def test_sim_enip_needs_cm1_firmware():
    out = _run("sim", "--no-state", "--enip")
    assert out.returncode == 2 and "--firmware cm1" in out.stderr


def test_enip_option_value_is_optional_and_parsed():
    assert optional_value_argv(["sim", "--enip"]) == ["sim", "--enip", "127.0.0.1"]
    assert optional_value_argv(["sim", "--enip", "--firmware", "cm1"])[2] == "127.0.0.1"
    assert optional_value_argv(["sim", "--enip", "0.0.0.0"]) == ["sim", "--enip", "0.0.0.0"]
    assert parse_enip("127.0.0.1") == ("127.0.0.1", 44818)
    assert parse_enip("0.0.0.0:0") == ("0.0.0.0", 0)
    assert parse_enip("4000") == ("127.0.0.1", 4000)
