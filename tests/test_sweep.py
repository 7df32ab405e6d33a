"""``coolmuscle sweep`` (docs/batch.md): one script over a grid of values.

tests/data/batch/sweep/move.cml is the 2.1 operation example (cml-users-guide.txt 2.1)
with ``S.1={SPEED}`` and ``A.1={ACCEL}``; load.toml (docs/machine-file.md) sweeps the
load's inertia.  Each row's figures are checked against a single ``coolmuscle run`` of
that combination: its ``--trace`` file (final position, peak speed and torque, the
in-position instants from the Ux column, 6.6 ?99) and a ``?71`` temperature query.
"""

from __future__ import annotations

import csv
import itertools
from pathlib import Path

import pytest

from cli_support import cli

DATA = Path(__file__).parent / "data" / "batch" / "sweep"
SCRIPT = DATA / "move.cml"
MACHINE = DATA / "load.toml"
SPEEDS = ("100", "250", "400")
ACCELS = ("50", "300")
NUMBERS = ("m1.final_position", "m1.peak_speed", "m1.peak_torque")


def trace_figures(trace: Path) -> dict[str, str]:
    """The figures read back from a ``coolmuscle run --trace`` CSV, as text."""
    rows = list(csv.DictReader(trace.open()))
    speeds = [r["m1.speed"].lstrip("-") for r in rows]
    torques = [r["m1.torque"].lstrip("-") for r in rows]
    arrivals, before = [], True
    for r in rows:
        now = bool(int(r["m1.status"]) & 8)
        if now and not before:
            arrivals.append(f"{float(r['time_s']):.6f}")
        before = now
    alarms = 0
    for r in rows:
        alarms |= int(r["m1.status"]) & (1 | 2 | 4 | 64 | 128)
    return {
        "duration_s": rows[-1]["time_s"],
        "m1.final_position": rows[-1]["m1.position"],
        "m1.peak_speed": max(speeds, key=float),
        "m1.peak_torque": max(torques, key=float),
        "m1.in_position": ";".join(arrivals),
        "m1.alarms": "" if not alarms else str(alarms),
    }


def test_a_3_by_2_sweep_gives_6_rows_with_the_figures_of_single_runs(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    results = tmp_path / "sweep.csv"
    machine = tmp_path / "load.toml"
    machine.write_text(MACHINE.read_text().replace("{INERTIA}", "4e-5"))
    code, out, err = cli(capsys, "sweep", str(SCRIPT), "--vary", "SPEED=" + ",".join(SPEEDS),
                         "--vary", "ACCEL=" + ",".join(ACCELS), "--machine", str(machine),
                         "--jobs", "2", "--results", str(results))
    assert code == 0, err
    rows = list(csv.DictReader(results.open()))
    assert len(rows) == 6
    assert [(r["SPEED"], r["ACCEL"]) for r in rows] == list(itertools.product(SPEEDS, ACCELS))
    for row in rows:
        single = tmp_path / f"run-{row['SPEED']}-{row['ACCEL']}.cml"
        text = SCRIPT.read_text().replace("{SPEED}", row["SPEED"]).replace(
            "{ACCEL}", row["ACCEL"])
        single.write_text(text)
        trace = single.with_suffix(".csv")
        code, _, err = cli(capsys, "run", str(single), "--machine", str(machine),
                           "--trace", str(trace))
        assert code == 0, err
        expected = trace_figures(trace)
        assert row["status"] == "ran" and row["first_difference"] == ""
        for name, value in expected.items():
            if name in NUMBERS:  # both files write 6 decimals: equal to their rounding
                assert float(row[name]) == pytest.approx(float(value), abs=1e-6), name
            else:
                assert row[name] == value, (row["SPEED"], row["ACCEL"], name)
        # never above S (x 100 pps, 2.1); S=100 is reached within the 20000 pulses
        peak = float(row["m1.peak_speed"])
        assert peak <= 100 * int(row["SPEED"]) + 1e-6
        if row["SPEED"] == "100":
            assert peak == pytest.approx(10000)
        assert len(row["m1.in_position"].split(";")) == 1
        # ?71 after the run: the temperature it ended at (no heating to speak of here)
        single.write_text(text + "?71.1\n")
        code, printed, _ = cli(capsys, "run", str(single), "--machine", str(machine))
        assert f"< Temp.1={row['m1.peak_temperature']}" in printed


def test_the_machine_file_is_swept_too_and_the_plot_is_drawn(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    results, plot = tmp_path / "s.csv", tmp_path / "torque.png"
    code, _, err = cli(capsys, "sweep", str(SCRIPT), "--vary", "SPEED=200",
                       "--vary", "ACCEL=100", "--vary", "INERTIA=1e-5,2e-5,4e-4",
                       "--machine", str(MACHINE), "--jobs", "1", "--results", str(results),
                       "--plot", str(plot), "--figure", "peak_torque")
    assert code == 0, err
    torques = [float(r["m1.peak_torque"]) for r in csv.DictReader(results.open())]
    assert torques == sorted(torques) and torques[0] < torques[-1]  # more inertia, more Ix
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_local_processes_and_this_process_give_the_same_bytes(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    one, two = tmp_path / "one.csv", tmp_path / "two.csv"
    common = [str(SCRIPT), "--vary", "SPEED=100,300", "--vary", "ACCEL=50,300",
              "--machine", str(MACHINE), "--vary", "INERTIA=1e-5"]
    assert cli(capsys, "sweep", *common, "--jobs", "1", "--results", str(one))[0] == 0
    assert cli(capsys, "sweep", *common, "--jobs", "2", "--results", str(two))[0] == 0
    assert one.read_bytes() == two.read_bytes()


@pytest.mark.parametrize("vary, message", [
    (["--vary", "SPEED=100"], "{ACCEL} has no --vary ACCEL=V1,V2,..."),
    (["--vary", "SPEED=100", "--vary", "ACCEL=1", "--vary", "K=1"],
     "--vary K: {K} appears neither in"),
    (["--vary", "SPEED=100,,200", "--vary", "ACCEL=1"], "--vary SPEED: empty value"),
    (["--vary", "SPEED", "--vary", "ACCEL=1"], "write NAME=V1,V2,..."),
    (["--vary", "SPEED=1", "--vary", "SPEED=2", "--vary", "ACCEL=1"], "given twice"),
    # a value that makes a line no CML: the motor would refuse it in silence, "1 passed"
    (["--vary", "SPEED=100,abc", "--vary", "ACCEL=1"],
     f"--vary SPEED=abc: line 3 of {SCRIPT} becomes 'S.1=abc', not CML (unknown operand "
     "'abc')"),
])
def test_bad_vary_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str],
                                         tmp_path: Path, vary: list[str],
                                         message: str) -> None:
    results = tmp_path / "r.csv"
    code, out, err = cli(capsys, "sweep", str(SCRIPT), *vary, "--results", str(results))
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("coolmuscle: error: ") and message in err
    assert not results.exists()


def test_a_placeholder_of_the_machine_file_needs_its_vary(
        capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = cli(capsys, "sweep", str(SCRIPT), "--vary", "SPEED=1", "--vary",
                       "ACCEL=1", "--machine", str(MACHINE))
    assert code == 2
    assert err == f"coolmuscle: error: {MACHINE}: {{INERTIA}} has no --vary INERTIA=V1,V2,...\n"


def test_a_substituted_value_that_breaks_the_machine_file_is_exit_2(
        capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = cli(capsys, "sweep", str(SCRIPT), "--vary", "SPEED=1", "--vary",
                       "ACCEL=1", "--machine", str(MACHINE), "--vary", "INERTIA=heavy")
    assert code == 2 and err.count("\n") == 1 and "load.toml" in err


@pytest.mark.parametrize("command", ["batch", "sweep"])
def test_help_shows_the_choices_of_firmware_and_motors(
        command: str, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "160")
    code, out, _ = cli(capsys, command, "--help")
    assert code == 0
    motors = next(line for line in out.splitlines() if "--motors" in line)
    firmware = next(line for line in out.splitlines() if "--firmware" in line)
    assert "[1<=x<=15]" in motors and "<cm2|rt3|cm1>" in firmware
    code, _, err = cli(capsys, command, str(SCRIPT), "--firmware", "cm3")
    assert code == 2 and "cm3" in err
