"""``coolmuscle run`` without typer (coolmuscle.tools.cli.entry): the same bytes, errors and
exit codes as the typer command, a start that loads only what the run needs
(the start of a run is a goal of docs/performance.md)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from coolmuscle.tools.cli.run import parse_run_args

SRC = str(Path(__file__).resolve().parents[1] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC, "COLUMNS": "200"}
ENV.pop("COOLMUSCLE_DEBUG", None)

BANK = "S1.1=100\nA1.1=100\nP1.1=1000\nB1.1\nS1.1, A1.1, P1.1\nEND\n[1.1\n@wait 1\n?96.1\n"
GOLDEN = "?96.1\n<< ?96.1\\r\\nPx.1=0\\r\\n\n"
WRONG = "?96.1\n<< ?96.1\\r\\nPx.1=5\\r\\n\n"

#: Python code run in a child: the quick entry point, or the typer command.
QUICK = "import sys; from coolmuscle.tools.cli.entry import main; main(sys.argv[1:])"
TYPER = "import sys; from coolmuscle.tools.cli.app import main; main(sys.argv[1:])"


def run(code: str, *args: str) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, env=ENV,
                          timeout=60)


@pytest.mark.parametrize("script, extra", [
    (BANK, ()), (BANK, ("--until", "3")), (BANK, ("--motors", "2", "--firmware=rt3")),
    (GOLDEN, ("--check",)), (GOLDEN, ()), (WRONG, ()), (BANK, ("--check",)),
    (BANK, ("--until", "-1")), (BANK, ("--motors", "16")), (BANK, ("--frobnicate",)),
    ("@wiat 1\n", ()),
])
def test_quick_run_answers_as_the_typer_command(tmp_path: Path, script: str,
                                                extra: tuple[str, ...]) -> None:
    path = tmp_path / "s.cml"
    path.write_text(script)
    quick, full = run(QUICK, "run", str(path), *extra), run(TYPER, "run", str(path), *extra)
    assert (quick.returncode, quick.stdout, quick.stderr) == \
        (full.returncode, full.stdout, full.stderr)
    assert b"Traceback" not in quick.stderr


def test_a_missing_script_is_the_same_one_line_error(tmp_path: Path) -> None:
    missing = str(tmp_path / "nope.cml")
    quick, full = run(QUICK, "run", missing), run(TYPER, "run", missing)
    assert quick.returncode == full.returncode == 2
    assert quick.stderr == full.stderr and quick.stderr.startswith(b"coolmuscle: error: ")


def test_a_plain_run_loads_no_command_line_library_nor_unused_protocols(tmp_path: Path) -> None:
    path = tmp_path / "s.cml"
    path.write_text(BANK)
    code = (QUICK + "; print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'typer', 'rich', 'click', 'asyncio', 'matplotlib', 'pymodbus', 'numpy', "
            "'pydantic'}), file=sys.stderr)")
    out = run(code, "run", str(path))
    assert out.returncode == 0, out.stderr
    assert out.stderr.strip().splitlines()[-1] == b"[]"


@pytest.mark.parametrize("args", [("--version",), ("version",)])
def test_version_answers_as_the_typer_command_without_loading_it(args: tuple[str, ...]) -> None:
    """Two lines: the version, then compiled or the sources and why."""
    code = QUICK + "; print(sorted({'typer', 'rich', 'click'} & set(sys.modules)), file=sys.stderr)"
    quick, full = run(code, *args), run(TYPER, *args)
    assert quick.returncode == full.returncode == 0
    assert quick.stdout == full.stdout
    version, hot = quick.stdout.decode().splitlines()
    assert version.startswith("coolmuscle ") and hot.startswith("hot modules: ")
    assert quick.stderr.strip() == b"[]"
    pure = subprocess.run([sys.executable, "-c", QUICK, *args], capture_output=True,
                          env={**ENV, "COOLMUSCLE_PURE": "1"}, timeout=60)
    assert pure.stdout.decode().splitlines()[1] == "hot modules: sources (COOLMUSCLE_PURE is set)"


def test_parse_run_args_leaves_anything_unusual_to_typer() -> None:
    assert parse_run_args(["run", "a.cml", "--until", "5", "--motors=3", "--check"]) == {
        "file": Path("a.cml"), "until": 5.0, "motors": 3, "check": True}
    for argv in (["run"], ["run", "a", "b"], ["run", "a", "--help"], ["run", "a", "--until"],
                 ["run", "a", "--until", "1e3"], ["run", "a", "--check", "--check"],
                 ["run", "a", "--motors", "0"], ["run", "a", "--firmware", "cm9"],
                 ["run", "a", "--trace", "-"], ["sim"], []):
        assert parse_run_args(argv) is None, argv


@pytest.mark.parametrize("extra, words", [
    (("--until", "nan"), "--until must be 0..1e+09 seconds, not nan"),
    (("--until", "inf"), "--until must be 0..1e+09 seconds, not inf"),
    (("--until", "1e308"), "--until must be 0..1e+09 seconds"),
    (("--trace-step", "1e-12", "--trace", "{tmp}/t.csv"), "--trace-step must be 1e-05..86400"),
    (("--trace-step", "inf", "--trace", "{tmp}/t.csv"), "--trace-step must be 1e-05..86400"),
])
def test_run_times_that_cannot_be_run_are_usage_errors(tmp_path: Path, extra: tuple[str, ...],
                                                       words: str) -> None:
    """A NaN, infinite or huge ``--until`` and a ``--trace-step`` too fine to end (1e-12 s
    never advanced: the run hung) or infinite: one line, exit 2, on both entry points
    (an attack found internal errors and hangs)."""
    path = tmp_path / "s.cml"
    path.write_text("S.1=10\n")
    args = [a.replace("{tmp}", str(tmp_path)) for a in extra]
    for code in (QUICK, TYPER):
        done = run(code, "run", str(path), *args)
        lines = done.stderr.decode().strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1 and words in lines[0], lines


def test_check_with_an_unknown_firmware_header_is_a_usage_error(tmp_path: Path) -> None:
    """``# coolmuscle: firmware=zz``: one line naming the header, exit 2 (was an
    internal error)."""
    path = tmp_path / "b.cml"
    path.write_text("# coolmuscle: firmware=zz\nB1.1\nP1.1\nEND\n")
    done = run(TYPER, "check", str(path))
    lines = done.stderr.decode().strip().splitlines()
    assert done.returncode == 2 and lines == [
        f"coolmuscle: error: {path}: '# coolmuscle: firmware=zz' is not cm2, rt3 or cm1"]


@pytest.mark.parametrize("scale", ["inf", "nan", "0", "1e300"])
def test_sim_time_scale_out_of_range_is_a_usage_error(scale: str) -> None:
    """``sim --time-scale inf`` was an internal error; anything not in (0, 1e6] is one
    line and exit 2 before anything starts."""
    done = subprocess.run([sys.executable, "-m", "coolmuscle", "sim", "--no-state", "--tcp",
                           "127.0.0.1:0", "--time-scale", scale], capture_output=True,
                          env=ENV, timeout=60, stdin=subprocess.DEVNULL)
    lines = done.stderr.decode().strip().splitlines()
    assert done.returncode == 2 and lines == [
        "coolmuscle: error: --time-scale must be above 0 and at most 1e+06"], lines


@pytest.mark.parametrize("command", ["run", "check"])
def test_a_device_is_not_read_as_a_script(command: str) -> None:
    """``run /dev/zero`` read until the memory ran out (killed); a device is one line and
    exit 2.  A pipe (``run <(...)``) is still read."""
    done = run(TYPER, command, "/dev/zero")
    lines = done.stderr.decode().strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and "a device, not a file" in lines[0]


def test_check_looks_at_each_bank_statement_a_bounded_number_of_times(monkeypatch) -> None:
    """3,000 bank definitions: the registers the file's banks write are worked out once a
    file (once a bank, the work was quadratic: 13.5 s for a 39 KB file; an attack found
    it).  Counted, not timed: ``writes`` is asked once per statement of the file."""
    from coolmuscle.client.program import parse_program
    from coolmuscle.tools.check import lint as check_mod
    from coolmuscle.tools.check.lint import check_program
    calls = [0]
    writes = check_mod.tree.writes

    def counted(statement):
        calls[0] += 1
        return writes(statement)
    monkeypatch.setattr(check_mod.tree, "writes", counted)
    program = parse_program("B1.1\nP.1=1\n\n" * 3000)
    report = check_program(program)
    assert len(report.banks) == 3000
    assert calls[0] <= 2 * 3000, calls[0]
