"""Bank upload with readback verification, and ``coolmuscle upload``, on the virtual
motor's bank model (2.2.2, 2.2.3; RT3 3.3 "query the banks after it has been sent to
verify that it is loaded correctly")."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from client_targets import Tcp
from coolmuscle import connect, connect_async
from coolmuscle.client import UploadError, parse_program
from coolmuscle.errors import NotAllowedInBankError
from coolmuscle.tools.cli import app as cli
from fixtures import run_coolmuscle

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
URL = "coolmuscle://?mode=fast&motors=2"
RT3 = "coolmuscle://?mode=fast&firmware=rt3"

PROGRAM = """\
S1.1=100
A1.1=100
P1.1=10000
P2.1=0
T1.1=1000
B1.1
S1.1, A1.1, P1.1   // to P1
T1.1
P2.1
END
V1.1="Px"
V2.1=5000
L1.1
V1.1> V2.1, S.1= S1.1, S.1= S2.1
V2.1>V3.1; V2.1=V3.1, T0.1
END
"""


def test_upload_sends_and_verifies_every_bank() -> None:
    progress: list[tuple[int, int]] = []
    with connect(URL) as m:
        result = m.upload(PROGRAM, progress=lambda done, total: progress.append((done, total)))
        assert result.ok and result.verified and result.banks == ["B1.1", "L1.1"]
        assert result.sent == 16 and progress[-1] == (16, 16) and len(progress) == 16
        assert m.read_bank(1) == ["S1.1, A1.1, P1.1", "T1.1", "P2.1"]
        assert m.read_bank(1, ladder=True) == ["V1.1>V2.1, S.1=S1.1, S.1=S2.1",
                                               "V2.1>V3.1;", "V2.1=V3.1, T0.1"]
        assert (m.read_register("P", 1), m.read_register("V", 1)) == (10000, "Px")
        assert m.read_all_banks() == {"B1.1": m.read_bank(1),
                                      "L1.1": m.read_bank(1, ladder=True)}


def test_a_bank_that_loads_differently_is_reported_line_by_line() -> None:
    """RT3 1.2 "INCORRECT": a number in a bank line; with K23 silent, only the readback
    tells that the motor did not take it (and what followed it)."""
    text = "V1.1=100\nB1.1\nA1.1=V1.1\nEND.1\nB2.1\nP1.1\nA1.1=100\nP2.1\nEND.1\n"
    with connect(RT3) as m:
        with pytest.raises(UploadError) as caught:
            m.upload(text)
    result = caught.value.result
    assert [d.format() for d in result.differences] == [
        "B2.1 line 2 (file line 7): missing on the motor: 'A1.1=100'",
        "B2.1 line 3 (file line 8): missing on the motor: 'P2.1'"]
    assert not result.errors and not result.ok and result.banks == ["B1.1", "B2.1"]


def test_errors_reported_while_defining_are_tied_to_their_file_line() -> None:
    text = "K23.1=17\nB2.1\nP1.1\n$.1\nP2.1\nEND\n"
    with connect(URL) as m:
        result = m.upload(text, check=False)
    assert [(line, type(error)) for line, error in result.errors] == \
        [(4, NotAllowedInBankError)]
    assert "$ is not allowed in bank" in str(result.errors[0][1])
    assert [d.format() for d in result.differences] == [
        "B2.1 line 2 (file line 4): missing on the motor: '$.1'",
        "B2.1 line 3 (file line 5): missing on the motor: 'P2.1'"]


def test_without_echo_lines_are_paced_and_still_verified() -> None:
    with connect(URL) as m:
        m.write_param(23, 9)                       # K23 8: no echo
        assert m.echo is False
        result = m.upload(PROGRAM, line_delay=0.01)
        assert result.ok and m.echo is False


def test_a_bank_ended_by_an_empty_line() -> None:
    program = parse_program("B3.1\nP1.1\nP2.1\n\nP.1=5\n")
    assert program.banks[0].closed_by == "blank" and len(program.items) == 2
    with connect(URL) as m:
        result = m.upload(program)
        assert result.ok and m.read_bank(3) == ["P1.1", "P2.1"]
        assert m.get_direct_data()["P"] == 5


def test_send_keeps_a_typed_definition_together() -> None:
    """Lines typed one by one: no fence may end up inside the bank."""
    with connect(URL) as m:
        for line in ("B4.1", "P1.1", "T1.1", "END"):
            assert m.send(line) == []
        assert m.read_bank(4) == ["P1.1", "T1.1"]


def test_async_upload() -> None:
    async def session() -> Any:
        async with await connect_async("coolmuscle://?scale=20") as m:
            result = await m.upload(PROGRAM)
            return result.banks, await m.read_bank(1)
    assert asyncio.run(asyncio.wait_for(session(), 30)) == (
        ["B1.1", "L1.1"], ["S1.1, A1.1, P1.1", "T1.1", "P2.1"])


# -- coolmuscle upload ------------------------------------------------------------------

def upload_cli(capsys: Any, *args: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_:
        cli.main(["upload", *args])
    out, err = capsys.readouterr()
    return int(exit_.value.code or 0), out, err


def test_upload_command_verifies_and_saves(capsys: Any) -> None:
    code, out, _ = upload_cli(capsys, str(EXAMPLES / "2.2-program-bank.cml"), "--port", URL,
                              "--save")
    assert code == 0
    assert out.strip().endswith("sent 12 line(s), B1.1 verified; saved on motor 1")


def test_upload_command_reports_exactly_what_differs(capsys: Any, tmp_path: Path) -> None:
    path = tmp_path / "rt3.cml"
    path.write_text("# coolmuscle: firmware=rt3\nV1.1=100\nB1.1\nA1.1=100\nEND.1\n")
    code, out, _ = upload_cli(capsys, str(path), "--port", RT3)
    assert code == 1
    assert out.splitlines() == [
        f"{path}: B1.1 line 1 (file line 4): missing on the motor: 'A1.1=100'",
        f"{path}: FAILED: 0 error(s), 1 difference(s) after sending 4 line(s)"]


def test_upload_command_refuses_a_file_with_syntax_errors(capsys: Any,
                                                          tmp_path: Path) -> None:
    bad = tmp_path / "bad.cml"
    bad.write_text("S1.1=100\nP1.1=\n")
    code, out, err = upload_cli(capsys, str(bad), "--port", URL)
    assert code == 1 and f"{bad}:2:6: expected an operand" in out
    assert "nothing was sent" in err
    assert upload_cli(capsys, str(tmp_path / "none.cml"), "--port", URL)[0] == 2


def test_upload_command_as_a_subprocess_over_tcp(tmp_path: Path) -> None:
    data = tmp_path / "data.cml"
    data.write_text("# data for a bank\nS1.1=250\nA1.1=1000\nP1.1=2500\nK44.1=150\n")
    target = Tcp()
    try:
        out = subprocess.run([sys.executable, "-m", "coolmuscle", "upload", str(data),
                              "--port", target.url], capture_output=True, text=True,
                             timeout=60, env={"PYTHONPATH": str(ROOT / "src"),
                                              "PATH": "/usr/bin:/bin"})
        assert out.returncode == 0, out.stderr
        assert out.stdout.strip() == f"{data}: sent 4 line(s), no banks verified"
        with connect(target.url) as m:
            assert (m.read_register("P", 1), m.read_param(44)) == (2500, 150)
    finally:
        target.close()


def test_upload_to_a_chain_without_the_motor_says_which_id_does_not_answer(
        capsys: Any, tmp_path: Path) -> None:
    """A file for ID1 and ID2 sent to a one-motor chain: "ID2 does not answer", before
    anything is sent (ID1 keeps its banks), not a timeout of an internal query."""
    path = tmp_path / "two.cml"
    path.write_text("B1.1\nS1.1, A1.1, P1.1\nEND.1\nB1.2\nS1.2, A1.2, P1.2\nEND.2\n")
    code, out, err = upload_cli(capsys, str(path), "--port", "coolmuscle://?mode=fast")
    assert (code, out) == (1, "")
    assert err == ("coolmuscle: error: ID2 does not answer (no reply to ?99.2 within 1 s): "
                   "the chain at coolmuscle://?mode=fast has no motor ID2, or it is off or "
                   "not wired; nothing was sent\n")


@pytest.mark.parametrize("command", ["upload", "term", "scan"])
def test_every_command_takes_host_port_where_a_port_is_expected(command: str,
                                                                tmp_path: Path) -> None:
    """``127.0.0.1:PORT``, as ``coolmuscle sim`` prints its address, is ``socket://`` for
    every command that talks to a motor (one parser: coolmuscle.tools.cli.ports)."""
    data = tmp_path / "data.cml"
    data.write_text("S1.1=250\n")
    target = Tcp()
    address = target.url.removeprefix("socket://")
    args = {"upload": ["upload", str(data), "--port", address],
            "term": ["term", address],
            "scan": ["scan", address, "--baud", "38400"]}[command]
    try:
        done = subprocess.run([sys.executable, "-m", "coolmuscle", *args], capture_output=True,
                              text=True, timeout=60, input="?96.1\n" if command == "term" else "",
                              env={"PYTHONPATH": str(ROOT / "src"), "PATH": "/usr/bin:/bin"})
    finally:
        target.close()
    said = done.stdout + done.stderr
    assert "No such file or directory" not in said and "could not open port" not in said
    if command == "upload":
        assert done.returncode == 0 and "sent 1 line(s)" in done.stdout
    elif command == "scan":
        assert "ID1" in said, said


def test_capture_takes_host_port_for_the_motor(tmp_path: Path) -> None:
    target = Tcp()
    address = target.url.removeprefix("socket://")
    capture = subprocess.Popen(
        [sys.executable, "-m", "coolmuscle", "capture", address, "--out",
         str(tmp_path / "c.cml"), "--listen", "0"], stderr=subprocess.PIPE, text=True,
        env={"PYTHONPATH": str(ROOT / "src"), "PATH": "/usr/bin:/bin"})
    try:
        assert capture.stderr is not None
        line = capture.stderr.readline()
        assert line.startswith("coolmuscle: capture ready: ") and \
            f"motor socket://{address} (38400 bit/s" in line, line
    finally:
        capture.send_signal(signal.SIGINT)
        capture.communicate(timeout=30)
        target.close()


def test_a_1000_listing_splits_into_banks() -> None:
    """The form the bank model prints (RT3 2.3: the listing also counts steps)."""
    from coolmuscle.client.banks import parse_bank_listing
    lines = ["B1.1", "A1.1=V1.1", "END.1", "B2.1", "END.1", "L2.1",
             "V1.1==P1.1, S0.1, CL3.1", "END.1", "Steps.1: program 4, ladder 13, total 17/200"]
    assert parse_bank_listing(lines) == {"B1.1": ["A1.1=V1.1"], "B2.1": [],
                                         "L2.1": ["V1.1==P1.1, S0.1, CL3.1"]}


def test_upload_of_an_rt3_file_to_a_cm2_hints_at_the_firmware() -> None:
    done = run_coolmuscle("upload", str(EXAMPLES / "rt3-7.2-analog-speed.cml"), "--port",
                          "coolmuscle://?mode=fast")
    assert done.returncode == 1
    assert "hint: the file is written for rt3" in done.stdout and "motor is cm2" in done.stdout


def test_the_baud_rate_option_has_one_name_everywhere(capsys: Any) -> None:
    """``--baud BPS`` as in capture and the desk commands; ``--baudrate`` still works
    (an alias the help does not show)."""
    for command in (["upload", "--help"], ["term", "--help"], ["capture", "--help"],
                    ["scan", "--help"]):
        with pytest.raises(SystemExit):
            cli.main(command)
        out = capsys.readouterr().out
        assert "--baud " in out and "--baudrate" not in out, command
    for option in ("--baud", "--baudrate"):
        code, out, _ = upload_cli(capsys, str(EXAMPLES / "2.1-operation.cml"), "--port", URL,
                                  option, "38400")
        assert code == 0, out
