"""The ``coolmuscle`` command: ``sim`` as a real subprocess, ``run`` in-process and as a
subprocess; its conventions (flags without a value, ``--version``, a script's
``# coolmuscle:`` line against options) and the K81 switch said in plain words and
undone by ``sim --reset`` (cml-users-guide.txt 5.6.1, 5.6.9; docs/fidelity.md "K81
persists")."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pexpect
import pytest
import serial

from coolmuscle import __version__
from coolmuscle.tools.cli import app as cli
from fakes import ROUNDTRIP, fake_factory
from fixtures import ChainFactory, SimFactory, run_coolmuscle

ROOT = Path(__file__).resolve().parents[1]
SRC = str(ROOT / "src")
ENV = {**os.environ, "PYTHONPATH": SRC, "COLUMNS": "200"}
ENV.pop("COOLMUSCLE_DEBUG", None)


def spawn_sim(*args: str) -> pexpect.spawn:
    return pexpect.spawn(sys.executable, ["-m", "coolmuscle", "sim", *args], env=ENV,
                         timeout=15, encoding="utf-8")


def tcp_echo(port: int, data: bytes, want: bytes) -> bytes:
    """Send ``data``; read until ``want`` has arrived (the motor may say more after it)."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall(data)
        got = b""
        while want not in got:
            chunk = sock.recv(4096)
            assert chunk, got
            got += chunk
        return got


# -- sim --------------------------------------------------------------------
def test_sim_prints_the_banner_serves_tcp_and_stops_on_sigterm() -> None:
    child = spawn_sim("--tcp", "0", "--no-state")
    try:
        child.expect(r"coolmuscle: virtual CM2 ID1 ready")
        child.expect(r"tcp: 127\.0\.0\.1:(\d+)\s+\(state: none, not saved\)")
        port = int(child.match.group(1))
        assert tcp_echo(port, b"?96.1\r", b"?96.1\r\n").startswith(b"?96.1\r\n")
        child.kill(signal.SIGTERM)
        child.expect("coolmuscle: stopped")
        child.expect(pexpect.EOF)
        child.close()
        assert child.exitstatus == 0
        assert "Traceback" not in (child.before or "")
    finally:
        if child.isalive():
            child.terminate(force=True)


def test_sim_stops_on_ctrl_c_and_serves_a_pty_link(tmp_path: Path) -> None:
    link = tmp_path / "cm-port"
    state = tmp_path / "state"
    child = spawn_sim("--pty-link", str(link), "--state", str(state), "--motors", "3",
                      "--firmware", "rt3")
    try:
        child.expect(r"coolmuscle: virtual RT3 ID1-ID3 ready")
        child.expect(r"pty: (\S+) -> (/dev/\S+)\s+\(state: (.+)\)")
        assert child.match.group(1) == str(link)
        assert child.match.group(3).strip() == str(state) and state.is_dir()
        with serial.Serial(str(link), timeout=2) as port:
            port.write(b"?96.1\r")
            assert port.read_until(b"\r\n") == b"?96.1\r\n"
        child.sendintr()
        child.expect("coolmuscle: stopped")
        child.expect(pexpect.EOF)
        child.close()
        assert child.exitstatus == 0
        assert not link.is_symlink()
    finally:
        if child.isalive():
            child.terminate(force=True)


def test_sim_stdio_keeps_stdout_for_motor_bytes() -> None:
    out = subprocess.run([sys.executable, "-m", "coolmuscle", "sim", "--stdio", "--no-state"],
                         input=b"?96.1\r", capture_output=True, env=ENV, timeout=30)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith(b"?96.1\r\n")    # the echo; the reply depends on the model
    assert b"virtual CM2 ID1 ready" in out.stderr and b"stdio: stdin/stdout" in out.stderr


def test_sim_port_in_use_is_a_one_line_error() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        out = subprocess.run([sys.executable, "-m", "coolmuscle", "sim", "--tcp", str(port),
                              "--no-state"], capture_output=True, text=True, env=ENV, timeout=30)
    assert out.returncode == 1
    assert re.fullmatch(rf"coolmuscle: error: tcp: cannot listen on 127\.0\.0\.1:{port}: .*\n",
                        out.stderr), out.stderr


# -- run, in process ----------------------------------------------------------
@pytest.fixture
def fake_chain(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(cli, "chain_factory", fake_factory())


def coolmuscle(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as info:
        cli.main(list(args))
    out, err = capsys.readouterr()
    code = info.value.code
    return (code if isinstance(code, int) else 0 if code is None else 1), out, err


@pytest.fixture
def roundtrip(tmp_path: Path) -> Path:
    path = tmp_path / "roundtrip.cml"
    path.write_text(ROUNDTRIP)
    return path


def test_run_prints_every_line_with_its_virtual_time(fake_chain: None, roundtrip: Path,
                                                     capsys: Any) -> None:
    code, out, err = coolmuscle(capsys, "run", str(roundtrip))
    assert code == 0, err
    lines = out.splitlines()
    assert lines[:3] == ["   0.000000 > ?96.1", "   0.000000 < ?96.1", "   0.000000 < Px.1=1"]
    assert "   1.100000 < Ux.1=8" in lines
    assert "ok: 7 expectation(s) matched" in err


def test_run_check_prints_only_the_verdict(fake_chain: None, roundtrip: Path, capsys: Any) -> None:
    code, out, _ = coolmuscle(capsys, "run", str(roundtrip), "--check")
    assert code == 0
    assert out == "coolmuscle: ok: 7 expectation(s) matched, ended at 1.100000 s\n"


def test_run_mismatch_exits_1_with_the_first_difference(fake_chain: None, tmp_path: Path,
                                                        capsys: Any) -> None:
    path = tmp_path / "bad.cml"
    path.write_text("?96.1\n<< ?96.1\\r\\n\n<< Px.1=9\\r\\n\n")
    code, out, err = coolmuscle(capsys, "run", str(path))
    assert code == 1
    assert err.startswith('coolmuscle: FAIL line 3: expected "Px.1=9\\r\\n"')
    assert "Traceback" not in out + err


def test_run_until_timeout_has_a_clear_message(fake_chain: None, tmp_path: Path,
                                               capsys: Any) -> None:
    path = tmp_path / "wait.cml"
    path.write_text("?96.1\n@until Ux.1=8 0.5\n")
    code, _, err = coolmuscle(capsys, "run", str(path))
    assert code == 1
    assert "line 2: @until 'Ux.1=8' timed out after 0.5 s" in err


def test_run_until_option_and_record(fake_chain: None, tmp_path: Path, capsys: Any) -> None:
    path = tmp_path / "move.cml"
    path.write_text("^.1\n")
    record = tmp_path / "golden.cml"
    code, out, _ = coolmuscle(capsys, "run", str(path), "--until", "2", "--record", str(record))
    assert code == 0 and out.splitlines()[-1] == "   1.100000 < Ux.1=8"
    assert record.read_text() == "^.1\n<< ^.1\\r\\n\n@wait 2\n<< Ux.1=8\\r\\n\n"
    code, _, _ = coolmuscle(capsys, "run", str(record), "--check")
    assert code == 0


@pytest.mark.parametrize("args, code, message", [
    (["run", "{tmp}/missing.cml"], 2, "cannot read script"),
    (["run", "{tmp}/bad.cml"], 2, "line 1: unknown directive @bogus"),
    (["run", "{tmp}/plain.cml", "--check"], 2, "--check needs a script with '<<' expectations"),
    (["run", "{tmp}/plain.cml", "--trace", "{tmp}/t.csv"], 2, "no trace recorder"),
    (["run", "{tmp}/plain.cml", "--plot", "{tmp}/t.png"], 2, "no trace recorder"),
    (["sim", "--state", "{tmp}", "--no-state"], 2, "exclude each other"),
    (["sim", "--tcp", "nope"], 2, "--tcp: bad TCP address 'nope'"),
])
def test_errors_are_one_line_messages(fake_chain: None, tmp_path: Path, capsys: Any,
                                      args: list[str], code: int, message: str) -> None:
    (tmp_path / "bad.cml").write_text("@bogus\n")
    (tmp_path / "plain.cml").write_text("?96.1\n")
    got, out, err = coolmuscle(capsys, *[a.replace("{tmp}", str(tmp_path)) for a in args])
    assert got == code
    assert message in err and err.count("\n") == 1 and err.startswith("coolmuscle: error: ")
    assert "Traceback" not in out + err


def test_bad_option_values_are_usage_errors(capsys: Any) -> None:
    code, _, err = coolmuscle(capsys, "run", "x.cml", "--motors", "99")
    assert code == 2 and "Traceback" not in err


def test_an_internal_error_is_one_line_too(monkeypatch: pytest.MonkeyPatch, roundtrip: Path,
                                           capsys: Any) -> None:
    def broken(*args: Any, **kwargs: Any) -> Any:
        raise RuntimeError("kaputt")
    monkeypatch.setattr(cli, "chain_factory", broken)
    code, _, err = coolmuscle(capsys, "run", str(roundtrip))
    assert code == 70
    assert err == ("coolmuscle: error: internal error: RuntimeError: kaputt "
                   "(COOLMUSCLE_DEBUG=1 shows a traceback)\n")


def test_version(capsys: Any) -> None:
    """The version and the hot modules' line (compiled here: the editable install
    compiled them; docs/performance.md)."""
    from coolmuscle import __version__, _accel
    code, out, _ = coolmuscle(capsys, "version")
    assert code == 0 and out == f"coolmuscle {__version__}\n{_accel.describe()}\n"
    assert _accel.describe().startswith(("hot modules: compiled (", "hot modules: sources ("))


# -- run, as a subprocess with the real chain -----------------------------------
def test_python_m_coolmuscle_run_with_the_real_chain(tmp_path: Path) -> None:
    path = tmp_path / "echo.cml"
    path.write_text("# the host line echoes what it receives\n?96.1\n@wait 0.5\n")
    start = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "coolmuscle", "run", str(path)],
                         capture_output=True, text=True, env=ENV, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[:2] == ["   0.000000 > ?96.1", "   0.000000 < ?96.1"]
    assert time.monotonic() - start < 30


def test_sim_stdio_on_a_terminal_echoes_as_typed_and_stops_on_ctrl_c() -> None:
    child = pexpect.spawn(sys.executable, ["-m", "coolmuscle", "sim", "--stdio", "--no-state"],
                          env=ENV, timeout=15)
    try:
        child.expect(rb"\(state: none, not saved\)")
        child.send(b"?96")
        child.expect(rb"\?96")           # the motor's echo, byte by byte (the tty echoes nothing)
        child.send(b".1\r")
        child.expect(rb"\.1\r")
        child.sendintr()
        child.expect(b"coolmuscle: stopped")
        child.expect(pexpect.EOF)
        child.close()
        assert child.exitstatus == 0
    finally:
        if child.isalive():
            child.terminate(force=True)


# -- the K81 switch, said in plain words ----------------------------------------------
def _ask(port: int, line: bytes) -> bytes:
    """What the sim says to ``line`` on TCP within a second (until a ``Px.1=``)."""
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
        except TimeoutError:
            pass
        return got


def test_5_6_9_k81_kept_in_the_state_is_said_and_sim_reset_brings_the_text_back(
        tmp_path: Path, make_chain: ChainFactory, served_sim: SimFactory) -> None:
    # 5.6.1 / ch. 3 K81: K81 != 0 puts COM0 in Modbus mode; the motor keeps its K values
    chain = make_chain(state_dir=tmp_path)
    chain.set_param(1, 81, 1)
    chain.close()                                         # one chain per state directory
    sim = served_sim(state=tmp_path)
    assert _ask(sim.port, b"?96.1\r") == b""             # Modbus: no text answer
    note = sim.wait_for(r"note: .*\(5\.6\.9\)\.").group(0)
    assert "K81.1=1" in note and "not CML text" in note and "--reset" in note
    assert sim.stop() == 0
    sim = served_sim("--reset", state=tmp_path)
    assert b"Px.1=0" in _ask(sim.port, b"?96.1\r") and "note:" not in sim.text
    assert sim.stop() == 0
    sim = served_sim(state=tmp_path)                      # the reset was saved
    assert b"Px.1=0" in _ask(sim.port, b"?96.1\r") and "note:" not in sim.text
    assert sim.stop() == 0


def test_sim_reset_recovers_a_damaged_store_keeping_it_aside(
        tmp_path: Path, served_sim: SimFactory) -> None:
    """A store file damaged beyond reading: without --reset the error says exactly what
    to do; ``sim --reset`` keeps the damaged file aside (nothing saved is deleted),
    says so, and serves factory settings, which it saves from then on."""
    damaged = tmp_path / "coolmuscle.sqlite3"
    junk = bytes(range(256)) * 20
    damaged.write_bytes(junk)
    failed = run_coolmuscle("run", str(ROOT / "examples" / "2.1-operation.cml"),
                            "--state", str(tmp_path))
    assert failed.returncode == 1
    assert failed.stderr == (
        f"coolmuscle: error: {damaged} is not a usable coolmuscle store: file is not a "
        f"database; move it aside (mv {damaged} {damaged}.bad) to start with defaults, or "
        "start coolmuscle sim with --reset (it keeps the file aside)\n")
    sim = served_sim("--reset", state=tmp_path)
    assert b"Px.1=0" in _ask(sim.port, b"?96.1\r")
    assert (f"coolmuscle: state reset: {damaged} is not a usable coolmuscle store: file is "
            f"not a database: kept it as {damaged}.bad; {tmp_path} holds factory settings"
            ) in sim.text
    assert sim.stop() == 0
    assert (tmp_path / "coolmuscle.sqlite3.bad").read_bytes() == junk
    damaged.write_bytes(junk)                             # damaged again: a second copy
    sim = served_sim("--reset", state=tmp_path)
    assert f"kept it as {damaged}.bad.1;" in sim.text
    assert sim.stop() == 0
    assert (tmp_path / "coolmuscle.sqlite3.bad.1").read_bytes() == junk


def test_the_demo_serves_from_its_own_state_directory() -> None:
    demo = (ROOT / "scripts" / "demo").read_text()
    assert 'sim --state "$ROOT/out/demo-state"' in demo


# -- conventions: flags, --version, a script's own defaults ------------------------------
def test_flags_show_no_value_and_there_is_a_version_option() -> None:
    help_text = run_coolmuscle("sim", "--help").stdout
    assert "--pty" in help_text and "<bool>" not in help_text
    assert "[HOST:]PORT" in help_text                      # options with values keep theirs
    done = run_coolmuscle("--version")
    version, hot = done.stdout.splitlines()
    assert done.returncode == 0 and version == f"coolmuscle {__version__}"
    assert hot.startswith(("hot modules: compiled (", "hot modules: sources ("))


def test_a_scripts_coolmuscle_line_is_the_default_and_an_option_wins_with_a_note() -> None:
    arc = str(ROOT / "examples" / "4.4.1-circular-radius.cml")   # "# coolmuscle: motors=2"
    done = run_coolmuscle("run", arc)
    assert done.returncode == 0 and "Px.2=" in done.stdout and "note" not in done.stderr
    done = run_coolmuscle("run", arc, "--motors", "1")
    assert "note: --motors 1 overrides the script's motors=2" in done.stderr
    assert "Px.2=" not in done.stdout
