"""The first hour of a newcomer: what a person following README.md meets.

The K81 switch said in plain words and undone by ``sim --reset`` (5.6.1, 5.6.9);
errors found before anything runs; CLI conventions (flags without a value, --version,
a script's ``# coolmuscle:`` line against options); plots titled and labelled.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import matplotlib.figure
import pexpect
import pytest

import coolmuscle
from coolmuscle.chain.daisy import Chain
from coolmuscle.errors import CoolMuscleError, InvalidArgumentError, TransportError
from coolmuscle.tools.cli import app as cli
from coolmuscle.tools.script.runner import ScriptError, run_script

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
ENV = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "COLUMNS": "200"}
ENV.pop("COOLMUSCLE_DEBUG", None)


def _cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "coolmuscle", *args], env=ENV, cwd=cwd,
                          capture_output=True, text=True, timeout=60)


def _sim(*args: str) -> tuple[pexpect.spawn, str, int]:
    child = pexpect.spawn(sys.executable, ["-m", "coolmuscle", "sim", "--tcp", "0", *args],
                          env=ENV, timeout=15, encoding="utf-8")
    child.expect(r"tcp: 127\.0\.0\.1:(\d+)")
    port = int(child.match.group(1))
    child.expect([r"\n", pexpect.TIMEOUT], timeout=0.5)
    try:
        child.expect(r"note: .*\(5\.6\.9\)\.", timeout=0.5)
        note = child.match.group(0)
    except pexpect.TIMEOUT:
        note = ""
    return child, note, port


def _stop(child: pexpect.spawn) -> None:
    child.kill(signal.SIGINT)
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 0, child.before


def _ask(port: int, line: bytes) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.settimeout(1.0)
        sock.sendall(line)
        got = b""
        try:
            while b"Px.1=" not in got:
                chunk = sock.recv(4096)
                if not chunk:
                    break
                got += chunk
        except socket.timeout:
            pass
        return got


# -- 1. the Modbus switch K81 ----------------------------------------------------------

def test_5_6_9_k81_kept_in_the_state_is_said_and_sim_reset_brings_the_text_back(
        tmp_path: Path) -> None:
    # 5.6.1 / ch. 3 K81: K81 != 0 puts COM0 in Modbus mode; the motor keeps its K values
    chain = Chain(state_dir=tmp_path)
    chain.set_param(1, 81, 1)
    chain.close()
    child, note, port = _sim("--state", str(tmp_path))
    try:
        assert "K81.1=1" in note and "not CML text" in note and "--reset" in note
        assert _ask(port, b"?96.1\r") == b""             # Modbus: no text answer
    finally:
        _stop(child)
    child, note, port = _sim("--state", str(tmp_path), "--reset")
    try:
        assert note == ""
        assert b"Px.1=0" in _ask(port, b"?96.1\r")
    finally:
        _stop(child)
    child, note, port = _sim("--state", str(tmp_path))     # the reset was saved
    try:
        assert note == "" and b"Px.1=0" in _ask(port, b"?96.1\r")
    finally:
        _stop(child)


def test_the_demo_serves_from_its_own_state_directory() -> None:
    demo = (ROOT / "scripts" / "demo").read_text()
    assert 'sim --state "$ROOT/out/demo-state"' in demo


# -- 2. Python examples ------------------------------------------------------------------

def test_public_names_and_the_exception_tree() -> None:
    assert coolmuscle.Ux.IN_POSITION == 8 and coolmuscle.Version.__name__ == "Version"
    assert coolmuscle.CoolMuscleError is CoolMuscleError
    with coolmuscle.connect("coolmuscle://?mode=fast") as m:
        with pytest.raises(CoolMuscleError) as info:
            m.write_param(20, 99)
        assert isinstance(info.value, (InvalidArgumentError, ValueError))
        with pytest.raises(CoolMuscleError):
            m.write_param(23, 99999)
        version = m.version
        assert (version.motor, version.series) == (1, "CM2")


def test_run_script_refuses_a_path_that_names_no_file() -> None:
    with pytest.raises(ScriptError, match="no such script file"):
        run_script("tests/transcripts/example.cml", Chain())
    assert run_script(str(EXAMPLES / "2.1-operation.cml"), Chain()).ok


# -- 5. errors before anything runs -----------------------------------------------------

def test_plot_with_an_unknown_extension_fails_before_the_run(tmp_path: Path) -> None:
    done = _cli("run", str(EXAMPLES / "2.1-operation.cml"), "--plot", str(tmp_path / "x.jpgx"))
    assert done.returncode == 2
    assert done.stdout == ""                                # nothing ran
    assert "cannot plot to" in done.stderr and ".png" in done.stderr
    assert "internal error" not in done.stderr


def test_socket_url_without_a_port_names_the_form() -> None:
    with pytest.raises(TransportError, match=r"socket://HOST:PORT"):
        coolmuscle.connect("socket://127.0.0.1")
    done = _cli("upload", str(EXAMPLES / "2.1-operation.cml"), "--port", "socket://127.0.0.1")
    assert done.returncode == 1 and "socket://HOST:PORT" in done.stderr + done.stdout
    assert "NoneType" not in done.stderr + done.stdout


def test_upload_of_an_rt3_file_to_a_cm2_hints_at_the_firmware() -> None:
    done = _cli("upload", str(EXAMPLES / "rt3-7.2-analog-speed.cml"), "--port",
                "coolmuscle://?mode=fast")
    assert done.returncode == 1
    assert "hint: the file is written for rt3" in done.stdout and "motor is cm2" in done.stdout


def test_check_rejects_the_directives_run_rejects(tmp_path: Path) -> None:
    script = tmp_path / "typo.cml"
    script.write_text("S.1=10\n@wiat 1\n")
    done = _cli("check", str(script))
    assert done.returncode == 1
    assert f"{script}:2:1: error[script] unknown directive @wiat" in done.stdout
    assert _cli("run", str(script)).returncode == 2


# -- 6. CLI conventions ----------------------------------------------------------------

def test_flags_show_no_value_and_there_is_a_version_option() -> None:
    help_text = _cli("sim", "--help").stdout
    assert "--pty" in help_text and "<bool>" not in help_text
    assert "[HOST:]PORT" in help_text                      # options with values keep theirs
    done = _cli("--version")
    version, hot = done.stdout.splitlines()
    assert done.returncode == 0 and version == f"coolmuscle {coolmuscle.__version__}"
    assert hot.startswith(("hot modules: compiled (", "hot modules: sources ("))


def test_a_scripts_coolmuscle_line_is_the_default_and_an_option_wins_with_a_note() -> None:
    arc = str(EXAMPLES / "4.4.1-circular-radius.cml")            # "# coolmuscle: motors=2"
    done = _cli("run", arc)
    assert done.returncode == 0 and "Px.2=" in done.stdout and "note" not in done.stderr
    done = _cli("run", arc, "--motors", "1")
    assert "note: --motors 1 overrides the script's motors=2" in done.stderr
    assert "Px.2=" not in done.stdout


# -- 7. plots ------------------------------------------------------------------------------

@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    saved: list[Any] = []
    original = matplotlib.figure.Figure.savefig

    def keep(self: Any, *args: Any, **kwargs: Any) -> Any:
        saved.append(self)
        return original(self, *args, **kwargs)
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)
    return saved


def _legend_texts(fig: Any) -> set[str]:
    return {t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().texts}


def test_plot_title_legend_outputs_and_stopper(tmp_path: Path, figures: list[Any]) -> None:
    with pytest.raises(SystemExit) as info:
        cli.main(["run", str(EXAMPLES / "4.1.4-push-motion.cml"), "--plot",
                  str(tmp_path / "push.png")])
    assert info.value.code in (0, None)
    fig = figures[-1]
    assert fig._suptitle.get_text().startswith("4.1.4-push-motion.cml")
    legend = _legend_texts(fig)
    assert {"moving", "push", "push complete"} <= legend       # Ux 0, 32, 40 occur
    assert not legend & {"alarm", "emergency stop", "motor free"}
    timeline = fig.axes[-1]
    labels = [t.get_text() for t in timeline.get_yticklabels()]
    assert "status" in labels
    stoppers = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert any("stopper 11000" in t for t in stoppers)        # the pushed object


def test_plot_output_rows_name_their_k34_function(tmp_path: Path, figures: list[Any]) -> None:
    script = tmp_path / "out.cml"
    script.write_text("K34.1=31\nO2.1\nS.1=100\nA.1=100\nP.1=1000\n^.1\n@wait 1\n")
    with pytest.raises(SystemExit):
        cli.main(["run", str(script), "--plot", str(tmp_path / "o.png")])
    labels = [t.get_text() for t in figures[-1].axes[-1].get_yticklabels()]
    assert "OUT1 in-position" in labels and "OUT2 general" in labels


def test_xy_panel_draws_the_dashed_command_path(tmp_path: Path, figures: list[Any]) -> None:
    with pytest.raises(SystemExit):
        cli.main(["run", str(EXAMPLES / "4.4.1-circular-radius.cml"), "--plot",
                  str(tmp_path / "arc.png")])
    fig = figures[-1]
    xy = [ax for ax in fig.axes if "XY path" in ax.get_title()]
    assert len(xy) == 1 and "command dashed" in xy[0].get_title()
    dashed = [line for line in xy[0].get_lines() if line.get_linestyle() == "--"
              and len(line.get_xdata()) > 10]
    assert dashed and dashed[0].get_zorder() > 2                # drawn over the actual path
    assert "command" in _legend_texts(fig)
