"""``coolmuscle params diff A B``: two backups, a backup and the factory values of its
firmware (or of another one), a backup and a live motor; each K with its meaning."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_support import cli
from coolmuscle.tools.desk import render_backup
from desk_support import virtual_line

TITLE = "ID1 : CM2v3.10R.1 #0802A12345"


def _backup(path: Path, setup: list[str]) -> Path:
    line = virtual_line(setup)
    try:
        path.write_text(render_backup(line.read_chain()))
    finally:
        line.close()
    return path


def test_two_backups(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = _backup(tmp_path / "a.cml", ["K24.1=2000", "P15.1=100", "B1.1", "S1.1", "END"])
    b = _backup(tmp_path / "b.cml", ["K27.1=12", "P15.1=100"])
    code, out, _err = cli(capsys, "params", "diff", str(a), str(b))
    assert code == 1
    assert out == (
        f"--- {a}: ID1 cm2 ({TITLE})\n"
        f"+++ {b}: ID1 cm2 ({TITLE})\n"
        "ID1 K24: 2000 -> 1000   Rotation Pulse Output (pulses; 10..50000; factory 1000)\n"
        "    Rotation pulse output: an output (K34=7) turns on and off every this many "
        "pulses; quadrature when outputs 1 and 2 are both 7.\n"
        "ID1 K27: 0 -> 12   Input Functions at Quick Response Target Voltage (000000..999999 "
        "digit by digit; factory 0)\n"
        "    Input function at the quick response target level, a digit per input: 0 none, "
        "1 general use, 2 origin sensor, 3 manual feed CW, 4 manual feed CCW, 5 stop the "
        "ladder bank, 6 CW limit, 7 emergency stop, 8 terminate the program bank, 9 CCW "
        "limit.\n"
        "2 differences in the K parameters\n")
    code, out, _err = cli(capsys, "params", "diff", str(a), str(b), "--all")
    assert code == 1
    assert out.splitlines()[-2:] == ["ID1 B1: 1 line -> (none)",
                                     "3 differences in the K parameters, data and banks"]
    code, out, _err = cli(capsys, "params", "diff", str(a), str(a), "--all")
    assert (code, out.splitlines()[-1]) == (0, "no difference in the K parameters, data "
                                               "and banks")


def test_a_backup_and_the_factory_values(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    a = _backup(tmp_path / "a.cml", ["K23.1=17", "V1.1=\"ab\""])
    code, out, _err = cli(capsys, "params", "diff", str(a), "factory", "--all")
    assert code == 1
    assert out.splitlines()[1:] == [
        f"+++ factory: ID1 cm2 ({TITLE})",
        "ID1 K23: 17 -> 1   Status Report (0..31; factory 1)",
        "    Status report, a sum of: 1 in-position and alarm reports, 2 input changes, "
        "4 output changes, 8 no local echo, 16 confirmation and error messages.",
        'ID1 V1: "ab" -> 0',
        "2 differences in the K parameters, data and banks"]


def test_another_firmware_shows_the_parameters_that_are_not_the_same(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = _backup(tmp_path / "a.cml", [])
    code, out, _err = cli(capsys, "params", "diff", "factory:rt3", str(a))
    assert code == 1
    lines = out.splitlines()
    assert lines[0] == "--- factory:rt3: ID1 rt3 (ID1 : CM1v3.00R.1 #0000A00000)"
    assert "ID1 K85: 0 -> 0   not the same parameter: rt3 Logic bank executed when powered on " \
           "(0..30; factory 0) / cm2 Endian (0..3; factory 0)" in lines
    assert "ID1 K62: (none) -> 0   Ladder Logic Bank No. Executed when Powered ON (0..30; " \
           "factory 0)" in lines


def test_a_backup_and_a_live_motor(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = _backup(tmp_path / "a.cml", ["K24.1=2000"])
    code, out, _err = cli(capsys, "params", "diff", "coolmuscle://?mode=fast", str(a))
    assert code == 1
    assert out.splitlines()[2] == "ID1 K24: 1000 -> 2000   Rotation Pulse Output (pulses; " \
                                  "10..50000; factory 1000)"


@pytest.mark.parametrize("a, b, message", [
    ("factory", "factory", "one side of params diff must be a backup or a port, not both "
                           "factory"),
    ("factory:cm3", "{a}", "factory:cm3: the firmware is cm2, rt3 or cm1"),
    ("{missing}", "factory", "cannot read {missing}: No such file or directory"),
])
def test_bad_sides(tmp_path: Path, capsys: pytest.CaptureFixture[str], a: str, b: str,
                   message: str) -> None:
    names = {"a": str(_backup(tmp_path / "a.cml", [])),
             "missing": str(tmp_path / "missing.cml")}
    code, out, err = cli(capsys, "params", "diff", a.format(**names), b.format(**names))
    assert (code, out, err) == (2, "", f"coolmuscle: error: {message.format(**names)}\n")
