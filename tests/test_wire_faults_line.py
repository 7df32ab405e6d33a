"""Host-line wire faults as a host program sees them (docs/wire-faults.md): the host
library over ``coolmuscle://`` (virtual time), over TCP, the pty and RFC 2217 (the same
faults on every transport: they are applied where bytes leave the model), and
``coolmuscle term`` in a tmux pane.  Then determinism: a machine file's fault schedule
gives the same transcript bit for bit on two runs, and a run without faults is the
golden one.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from coolmuscle import connect
from coolmuscle.chain.daisy import Chain
from coolmuscle.errors import CoolMuscleTimeout, OutOfRangeError, ProtocolError
from coolmuscle.frontends.transports.pty import PtyTransport
from coolmuscle.frontends.transports.rfc2217 import Rfc2217Transport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport
from coolmuscle.tools.script.runner import run_script
from test_term import RED, Pane, line_with, term_env

STORM = """
[[wire.fault]]
door = "host-line"
kind = "drop"
probability = 0.2
seed = 3

[[wire.fault]]
door = "host-line"
kind = "garble"
probability = 0.2
seed = 4

[[wire.fault]]
door = "host-line"
kind = "split"
every = 3
pieces = 3
gap_ms = 2

[[wire.fault]]
door = "host-line"
kind = "delay"
every = 5
ms = 30
"""


def faults_of(m) -> Chain:
    return m.port.chain


def test_dropped_reply_raises_timeout_and_the_next_command_works():
    with connect("coolmuscle://?mode=fast", timeout=0.5, firmware="cm2") as m:
        faults_of(m).inject_wire_fault("host-line", "drop", count=1)
        with pytest.raises(CoolMuscleTimeout, match=r"no Px\.1= reply to '\?96\.1'"):
            m.get_position()
        assert m.get_position() == 0


def test_garbled_value_raises_protocol_error_and_the_next_command_works():
    with connect("coolmuscle://?mode=fast", timeout=0.5, firmware="cm2") as m:
        faults_of(m).inject_wire_fault("host-line", "garble", byte=-3, xor=0x40, count=1)
        with pytest.raises(ProtocolError, match=r"garbled reply 'Px\.1=p'"):
            m.get_position()
        assert m.get_position() == 0


@pytest.mark.parametrize("firmware", ["cm2", "rt3"])
@pytest.mark.parametrize("write", [False, True])
def test_a_dropped_read_back_is_a_timeout_not_a_missing_register(firmware, write):
    """The fence (``?96.1``) is answered, the register's reply is not: on the R type
    (CM2) an allocation could have removed P9 (2.1.2), so the library asks once more;
    either way the lost reply is a ``CoolMuscleTimeout``, and the next command works."""
    with connect("coolmuscle://?mode=fast", timeout=0.5, firmware=firmware) as m:
        m.write_register("P", 9, 0)                      # K37 and the firmware known
        faults_of(m).inject_wire_fault("host-line", "drop", count=1)
        with pytest.raises(CoolMuscleTimeout, match=r"no reply to P9\.1, though the "
                                                    r"\?96\.1 after it was answered"):
            m.write_register("P", 9, 5) if write else m.read_register("P", 9)
        assert m.read_register("P", 9) == (5 if write else 0)


def test_a_register_an_allocation_removed_is_still_out_of_range():
    with connect("coolmuscle://?mode=fast", timeout=0.5, firmware="cm2") as m:
        m.send("\\P5")                                   # P0..P5 only (2.1.2)
        with pytest.raises(OutOfRangeError, match=r"P9\.1: no such register"):
            m.read_register("P", 9)
        assert m.read_register("P", 5) == 0


def test_unreadable_reply_times_out_naming_what_came():
    with connect("coolmuscle://?mode=fast", timeout=0.5, firmware="cm2") as m:
        faults_of(m).inject_wire_fault("host-line", "garble", byte=0, xor=0x80, count=1)
        with pytest.raises(CoolMuscleTimeout, match=r"unreadable line"):
            m.get_position()
        assert m.get_position() == 0


def test_split_duplicate_delay_and_latency_are_absorbed_by_the_library():
    with connect("coolmuscle://?mode=fast", timeout=0.5, firmware="cm2") as m:
        chain = faults_of(m)
        chain.inject_wire_fault("host-line", "split", pieces=4, gap_ms=20, count=1)
        chain.inject_wire_fault("host-line", "duplicate", at=0, count=1)
        chain.inject_wire_fault("host-line", "latency", ms=16)
        m.write_register("P", 1, 1234)
        assert m.read_register("P", 1) == 1234
        assert m.get_position() == 0
        chain.inject_wire_fault("host-line", "delay", ms=300, count=1)
        assert m.get_status() is not None


def test_dead_line_then_back():
    with connect("coolmuscle://?mode=fast", timeout=0.5, firmware="cm2") as m:
        faults_of(m).inject_wire_fault("host-line", "dead", until=0.8)
        with pytest.raises(CoolMuscleTimeout):
            m.write_register("P", 1, 5)
        with pytest.raises(CoolMuscleTimeout):
            m.read_register("P", 1)
        assert m.read_register("P", 1) == 0          # the write never arrived


def test_url_takes_a_machine_file_with_wire_faults(tmp_path: Path):
    toml = tmp_path / "drop.toml"
    toml.write_text('[[wire.fault]]\ndoor = "host-line"\nkind = "drop"\ncount = 1\n')
    with connect(f"coolmuscle://?mode=fast&machine={toml}", timeout=0.5,
                 firmware="cm2") as m:
        with pytest.raises(CoolMuscleTimeout):
            m.get_position()
        assert m.get_position() == 0


def _served(tmp_path: Path, pace: bool = False) -> ServiceThread:
    return ServiceThread(lambda: Chain(pacing=pace), lambda: [
        TcpTransport(port=0), PtyTransport(link=str(tmp_path / "cm-pty")),
        Rfc2217Transport(port=0)]).start()


@pytest.fixture
def served_line(tmp_path: Path) -> Iterator[tuple[ServiceThread, str, str]]:
    st = _served(tmp_path)
    try:
        yield st, f"socket://127.0.0.1:{st.transports[0].info()['port']}", \
            str(tmp_path / "cm-pty")
    finally:
        st.stop()


@pytest.mark.peer
@pytest.mark.parametrize("transport, pace", [("tcp", False), ("pty", False),
                                             ("rfc2217", False), ("rfc2217", True)])
def test_the_same_faults_on_tcp_the_pty_and_rfc2217(tmp_path, transport, pace):
    """pyserial's ``socket://``, a pty and ``rfc2217://`` (also with wire pacing: the
    faults act on bytes sent at K20 in the motor's frame, the port set to the same)."""
    st = _served(tmp_path, pace)
    where = {"tcp": f"socket://127.0.0.1:{st.transports[0].info()['port']}",
             "pty": str(tmp_path / "cm-pty"),
             "rfc2217": f"rfc2217://127.0.0.1:{st.transports[2].info()['port']}"}
    try:
        _the_same_faults(st, where[transport])
    finally:
        st.stop()


def _the_same_faults(st: ServiceThread, url: str) -> None:
    with connect(url, timeout=0.5, firmware="cm2") as m:
        assert m.get_position() == 0
        st.call(lambda: st.chain.inject_wire_fault("host-line", "drop", count=1))
        with pytest.raises(CoolMuscleTimeout):
            m.get_position()
        assert m.get_position() == 0
        st.call(lambda: st.chain.inject_wire_fault("host-line", "garble", byte=-3,
                                                   xor=0x40, count=1))
        with pytest.raises(ProtocolError):
            m.get_position()
        assert m.get_position() == 0


@pytest.mark.peer
def test_term_says_what_happened(served_line, tmp_path):
    st, url, _ = served_line
    pane = Pane([sys.executable, "-m", "coolmuscle", "term", url], term_env(tmp_path))
    try:
        pane.prompt()
        pane.type("?96.1")
        pane.wait(r"Px\.1=0")
        pane.prompt()
        st.call(lambda: st.chain.inject_wire_fault("host-line", "drop", count=1))
        pane.type("?99.1")
        screen = pane.wait(r"no reply to '\?99\.1' within 1 s", colours=True)
        assert RED in line_with(screen, "no reply to")
        st.call(lambda: st.chain.inject_wire_fault("host-line", "garble", byte=-3,
                                                   xor=0x80, count=1))
        pane.type("?96.1")
        pane.wait(r"unreadable: 'Px\.1=°'")              # 0x30 ^ 0x80, latin-1
        st.call(lambda: st.chain.inject_wire_fault("host-line", "dead", until=2.0))
        pane.type("P1.1=5")
        pane.wait(r"no answer to 'P1\.1=5' within 1 s, not even its echo: is the line "
                  r"down\?")
        pane.keys("C-d")
    finally:
        pane.close()


@pytest.mark.peer
def test_term_from_a_pipe_says_which_reply_did_not_come(served_line, tmp_path):
    """Input from a pipe: the plain session prints what came and, before it ends, which
    query's reply did not come (the dropped one), then the next one's reply."""
    st, url, _ = served_line
    st.call(lambda: st.chain.inject_wire_fault("host-line", "drop", count=1))
    out = subprocess.run([sys.executable, "-m", "coolmuscle", "term", url, "--timeout",
                          "0.5"], input="?96.1\n", capture_output=True, text=True,
                         timeout=60, env=term_env(tmp_path))
    assert out.returncode == 0, out.stderr
    assert "no reply to '?96.1' within 0.5 s" in out.stdout, out.stdout
    out = subprocess.run([sys.executable, "-m", "coolmuscle", "term", url, "--timeout",
                          "0.5"], input="?96.1\n", capture_output=True, text=True,
                         timeout=60, env=term_env(tmp_path))
    assert "Px.1=0" in out.stdout and "no reply" not in out.stdout, out.stdout


def _run(script: str, machine: Path) -> tuple[str, bytes]:
    chain = Chain(machine=machine)
    try:
        result = run_script(script, chain)
    finally:
        chain.close()
    return result.format(), result.received


SCRIPT = "K23.1=17\n" + "?96.1\n?99.1\nP1.1=7\nP1.1\n" * 25 + \
         "S.1=100, A.1=100, P.1=5000, ^.1\n@wait 1\n" + "?96.1\n" * 10


def test_a_scheduled_fault_storm_gives_the_same_transcript_bit_for_bit(tmp_path):
    machine = tmp_path / "storm.toml"
    machine.write_text(STORM)
    first, second = _run(SCRIPT, machine), _run(SCRIPT, machine)
    assert first == second
    text = first[0]
    for kind in ("drop", "garble", "split", "delay"):
        assert f"host-line {kind}:" in text
    assert text.count("# wire fault") > 40


def test_without_faults_the_transcript_has_no_fault_notes(tmp_path):
    machine = tmp_path / "none.toml"
    machine.write_text("")
    text, received = _run(SCRIPT, machine)
    assert "# wire" not in text
    assert received.count(b"Px.1=0\r\n") == 25


def test_a_garbled_read_back_of_a_write_is_a_protocol_error_not_out_of_range():
    with connect("coolmuscle://?mode=fast", timeout=0.5, firmware="cm2") as m:
        m.write_register("P", 9, 1)                   # K37 read and kept
        # the read-back "P9.1=-344" with its '-' (0x2d) xor 0x02 = '/'
        faults_of(m).inject_wire_fault("host-line", "garble", byte=5, xor=0x02, count=1)
        with pytest.raises(ProtocolError, match=r"garbled reply 'P9\.1=/344'"):
            m.write_register("P", 9, -344)
        assert m.read_register("P", 9) == -344          # it was applied
