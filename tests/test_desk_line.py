"""The desk on a stand-in for a real motor: ``coolmuscle sim --pty --pace`` (a subprocess
on a pty of its own, wire-paced at the K20 rate, torn down after each test) and pyserial.

* scan finds its IDs and its rate (ch. 3 K20), again after K20 changes (at once, and
  through the K23 16 prompt "Change Baud Rate ?? XXX kbps (Y/N)"), on a chain of three,
  over TCP (HOST:PORT); scanning at the wrong rates changes nothing on the motor;
* backup -> factory reset (``sim --reset``) -> restore --save gives back the same bytes
  to every query a backup reads, and after a power cycle too (``$``, 2.1.2); the backup
  plays with ``coolmuscle run`` to the same answers.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from cli_support import cli
from coolmuscle.chain.daisy import Chain
from coolmuscle.tools.script.runner import run_script
from desk_support import StandIn, exchange, stand_in

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

TITLE = "ID{n} : CM2v3.10R.1 #0802A12345"


@pytest.fixture
def one_motor(tmp_path: Path) -> Iterator[StandIn]:
    with stand_in(tmp_path, "--pty", "--pace", "--no-state") as sim:
        yield sim


def test_scan_finds_the_motor_and_its_rate_also_after_k20_changes(
        one_motor: StandIn, capsys: pytest.CaptureFixture[str]) -> None:
    pty = one_motor.pty
    code, out, err = cli(capsys, "scan", pty)
    assert (code, out) == (0, f"ID1  K20=0 (38400 bit/s)  cm2  {TITLE.format(n=1)}\n")
    assert err.startswith(f"coolmuscle: 1 motor on {pty} at 38400 bit/s (")
    # K23 without 16: K20 changes at once (ch. 3 K20); the host must follow
    assert exchange(pty, ["K20.1=4"])[0] == b"K20.1=4\r\n"
    code, out, err = cli(capsys, "scan", pty)
    assert (code, out) == (0, f"ID1  K20=4 (115200 bit/s)  cm2  {TITLE.format(n=1)}\n")
    assert err.startswith(f"coolmuscle: 1 motor on {pty} at 115200 bit/s (")
    # K23 with 16: the motor asks first (ch. 3 K23 16), Y applies
    asked = exchange(pty, ["K23.1=17", "K20.1=2", "Y"], baud=115200)
    assert asked[1] == b"K20.1=2\r\nChange Baud Rate ?? 19.2 kbps (Y/N)\r\n"
    code, out, err = cli(capsys, "scan", pty)
    assert (code, out) == (0, f"ID1  K20=2 (19200 bit/s)  cm2  {TITLE.format(n=1)}\n")
    assert err.startswith(f"coolmuscle: 1 motor on {pty} at 19200 bit/s (")
    # the tries at the other rates changed nothing: servo on, in position
    assert exchange(pty, ["?99.1", "K23.1", "K24.1"], baud=19200) == \
        [b"?99.1\r\nUx.1=8\r\n", b"K23.1\r\nK23.1=17\r\n", b"K24.1\r\nK24.1=1000\r\n"]


def test_scan_a_chain_of_three_on_the_pty_and_over_tcp(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with stand_in(tmp_path, "--pty", "--pace", "--tcp", "0", "--motors", "3",
                  "--no-state") as sim:
        expected = "".join(f"ID{n}  K20=0 (38400 bit/s)  cm2  {TITLE.format(n=n)}\n"
                           for n in (1, 2, 3))
        code, out, err = cli(capsys, "scan", sim.pty)
        assert (code, out) == (0, expected)
        assert err.startswith(f"coolmuscle: 3 motors on {sim.pty} at 38400 bit/s (")
        code, out, err = cli(capsys, "scan", sim.tcp)
        assert (code, out) == (0, expected)
        assert err.startswith(f"coolmuscle: 3 motors on socket://{sim.tcp} (a socket: "
                              "no wire, no rate) (")


#: Every query a backup reads (reading.py), for ID1 and ID2.
QUERIES = [f"{q}.{n}" for n in (1, 2) for q in
           ("?90", "?P", "?N", "?R", "?S", "?A", "?M", "?T", "?V", "H0", "?", "?1000")]

SETUP = ["K24.1=2000", "P15.1=100", 'V1.1="a,b"', 'V2.1="Px"', "V3.1=-7", "H0.1=12",
         "S.1=50", "N7.1=-300", "B1.1", "S1.1,A1.1,P1.1", "END", "L2.1",
         "I1.1&&I2.1,O1.1", "END", "K37.2=7", "P3.2=1000000", "T4.2=250", "B5.2", "END",
         "K23.1=17", "K20.1=4", "Y"]


def _answers(pty: str) -> list[bytes]:
    return exchange(pty, QUERIES, baud=115200, quiet=0.15)


def test_backup_factory_reset_restore_gives_the_same_answers(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    state = tmp_path / "state"
    state.mkdir()
    backup = tmp_path / "motor.cml"
    args = ["--pty", "--pace", "--motors", "2", "--state", str(state)]
    with stand_in(tmp_path, *args) as sim:
        exchange(sim.pty, SETUP, quiet=0.15)
        before = _answers(sim.pty)
        assert b"K24.1=2000" in before[0]              # the setup's, at 115.2 kbps
        code, _out, err = cli(capsys, "backup", sim.pty, "-o", str(backup))
        assert code == 0, err
        assert err.startswith(f"coolmuscle: {backup}: ID1 cm2, ID2 cm2 (")
    with stand_in(tmp_path, *args, "--reset") as sim:
        assert exchange(sim.pty, ["K20.1"])[0] == b"K20.1\r\nK20.1=0\r\n"    # factory
        code, out, err = cli(capsys, "restore", str(backup), "--port", sim.pty, "--save")
        assert code == 0, out + err
        assert out.splitlines() == [
            "ID1 K parameters: 2 line(s) written, read back equal",
            "ID1 data: 7 line(s) written, read back equal",
            "ID1 banks: 6 line(s) written, read back equal",
            "ID2 K parameters: 1 line(s) written, read back equal",
            "ID2 data: 2 line(s) written, read back equal",
            "ID2 banks: 2 line(s) written, read back equal",
            "line: 1 line(s) written, read back equal",
            "ID1 save: saved", "ID2 save: saved"]
        assert _answers(sim.pty) == before
    with stand_in(tmp_path, *args) as sim:                 # a power cycle: what $ kept
        assert _answers(sim.pty) == before
    played = run_script(backup.read_text() + "\n".join(QUERIES) + "\n", Chain(motors=2))
    assert played.ok
    assert played.received.endswith(b"".join(before))
