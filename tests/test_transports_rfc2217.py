"""The host line as an RFC 2217 serial port (``sim --rfc2217``), driven by pyserial's
``rfc2217://`` client, the host library, ``term`` and ``scan``.

* unpaced: the CML exchange byte for byte, whatever rate the client sets;
* paced (``--pace``): at the motor's rate byte for byte; at another rate (ch. 3 K20), or
  another frame than the motor's 8 data bits, K82 parity, 1 stop bit (5.6.1, ch. 3 K82),
  each side reads exactly what the UART model makes of the other's bytes; a break reads
  as 0x00;
* the options a port server answers (data size, stop size, flow control, DTR/RTS,
  purge, the modem lines, the states asked for), 0xFF both ways, malformed options
  ignored with the data after them delivered;
* ``scan`` finds the motor's K20 rate by changing the client's rate over RFC 2217.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import serial

import coolmuscle
from cli_support import cli
from coolmuscle.chain.daisy import Chain
from coolmuscle.device.uart import Frame, as_read_at
from coolmuscle.frontends.transports.rfc2217 import Rfc2217Transport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.testing.served import ServedSim, child_env, wait_until
from coolmuscle.tools.desk.linescan import scan

IAC, SB, SE = 0xFF, 0xFA, 0xF0
COM_PORT = 44


class Served:
    """A chain behind an RFC 2217 port in this process; ``raw`` collects every chunk the
    motor sends as it leaves the motor (a listener with no port: what a matched host
    reads)."""

    def __init__(self, pacing: bool) -> None:
        self.st = ServiceThread(lambda: Chain(pacing=pacing),
                                lambda: [Rfc2217Transport(port=0)]).start()
        self.url = f"rfc2217://127.0.0.1:{self.st.transports[0].info()['port']}"
        self.raw: list[bytes] = []
        self.st.call(lambda: self.st.chain.host_line.add_listener(self.raw.append))

    def chunks(self) -> list[bytes]:
        """The motor's chunks so far (taken in the service's thread), and forget them."""
        def take() -> list[bytes]:
            got = list(self.raw)
            self.raw.clear()
            return got
        return self.st.call(take)

    def execute(self, line: str) -> None:
        self.st.call(lambda: self.st.chain.execute(line))


@pytest.fixture(params=[False, True], ids=["unpaced", "paced"])
def served(request: pytest.FixtureRequest) -> Iterator[Served]:
    made = Served(request.param)
    try:
        yield made
    finally:
        made.st.stop()


@pytest.fixture
def paced() -> Iterator[Served]:
    made = Served(True)
    try:
        yield made
    finally:
        made.st.stop()


def ask(port: Any, text: bytes, wait: float = 0.25) -> bytes:
    """Write ``text`` and read what came within ``wait`` s (more while bytes arrive)."""
    port.reset_input_buffer()
    port.write(text)
    got = b""
    deadline = time.monotonic() + wait
    while time.monotonic() < deadline:
        more = port.read(max(1, port.in_waiting))
        got += more
        if more:
            deadline = max(deadline, time.monotonic() + 0.1)
    return got


def test_the_cml_exchange_is_byte_exact(served: Served) -> None:
    with serial.serial_for_url(served.url, baudrate=38400, timeout=0.05) as port:
        assert ask(port, b"?96.1\r") == b"?96.1\r\nPx.1=0\r\n"
        assert ask(port, b"K37.1\rK20.1\r") == b"K37.1\r\nK37.1=3\r\nK20.1\r\nK20.1=0\r\n"


def test_without_pacing_the_rate_and_frame_have_no_effect() -> None:
    made = Served(False)
    try:
        with serial.serial_for_url(made.url, baudrate=9600, parity="E", bytesize=7,
                                   timeout=0.05) as port:
            assert ask(port, b"?96.1\r") == b"?96.1\r\nPx.1=0\r\n"
    finally:
        made.st.stop()


def test_at_another_rate_each_side_reads_garbage_as_a_uart_would(paced: Served) -> None:
    with serial.serial_for_url(paced.url, baudrate=9600, timeout=0.05) as port:
        paced.chunks()
        heard = ask(port, b"?96.1\r", wait=0.4)
        sent = paced.chunks()                 # what the motor sent: its echo of garbage
        assert sent and b"?96.1" not in b"".join(sent) and b"Px.1" not in b"".join(sent)
        assert heard == b"".join(as_read_at(chunk, 38400, 9600) for chunk in sent)
        port.baudrate = 38400                 # the client sets the motor's rate: answered
        assert ask(port, b"\r?96.1\r").endswith(b"?96.1\r\nPx.1=0\r\n")
        port.baudrate = 12345                 # any rate a UART takes, garbage too
        assert b"Px.1" not in ask(port, b"?96.1\r", wait=0.4)


def test_a_rate_no_serial_port_has_is_refused_and_the_line_stays_quick(
        paced: Served) -> None:
    """A client asking 4 Gbit/s (the field's largest value) is refused: its port keeps
    the rate it had, and the model does not spend seconds reading at it (the host line
    takes a host's rate within 50 bit/s .. 12 Mbit/s, docs/fidelity.md)."""
    with serial.serial_for_url(paced.url, baudrate=38400, timeout=0.05) as port, \
            serial.serial_for_url(paced.url, baudrate=38400, timeout=0.05) as other:
        with pytest.raises((serial.SerialException, ValueError)):
            port.baudrate = 0xFFFFFFFF
        start = time.monotonic()
        assert ask(other, b"?96.1\r") == b"?96.1\r\nPx.1=0\r\n"
        assert time.monotonic() - start < 2.0
        port.baudrate = 38400
        assert ask(port, b"\r?96.1\r").endswith(b"?96.1\r\nPx.1=0\r\n")


def test_the_motor_does_not_follow_the_clients_rate(paced: Served) -> None:
    with serial.serial_for_url(paced.url, baudrate=115200, timeout=0.05) as port:
        ask(port, b"\r?96.1\r", wait=0.4)
        assert paced.st.call(lambda: paced.st.chain.get_param(1, 20)) == 0   # ch. 3 K20
        paced.execute("K20.1=4")              # K20 changes the motor: now they match
        assert ask(port, b"\r?96.1\r").endswith(b"?96.1\r\nPx.1=0\r\n")


def test_a_parity_other_than_k82_reads_garbage_both_ways(paced: Served) -> None:
    with serial.serial_for_url(paced.url, baudrate=38400, timeout=0.05) as port:
        port.parity = serial.PARITY_EVEN      # the motor frames 8N1 (K82=0)
        paced.chunks()
        heard = ask(port, b"?96.1\r", wait=0.4)
        sent = paced.chunks()
        assert b"Px.1" not in b"".join(sent)
        assert heard == b"".join(as_read_at(chunk, 38400, 38400, Frame(), Frame(parity="E"))
                                 for chunk in sent)
        paced.execute("K82.1=1")              # the motor frames 8E1 now (ch. 3 K82)
        assert ask(port, b"\r?96.1\r").endswith(b"?96.1\r\nPx.1=0\r\n")
        port.parity = serial.PARITY_NONE
        assert b"Px.1" not in ask(port, b"\r?96.1\r", wait=0.4)


def test_a_seven_bit_port_reads_garbage_when_paced(paced: Served) -> None:
    with serial.serial_for_url(paced.url, baudrate=38400, bytesize=7,
                               stopbits=serial.STOPBITS_TWO, timeout=0.05) as port:
        assert b"Px.1" not in ask(port, b"?96.1\r", wait=0.4)
        port.bytesize = 8
        port.stopbits = serial.STOPBITS_ONE_POINT_FIVE   # a receiver checks one stop bit
        assert ask(port, b"\r?96.1\r").endswith(b"?96.1\r\nPx.1=0\r\n")


def test_a_break_reads_as_one_zero_byte_when_paced(paced: Served) -> None:
    with serial.serial_for_url(paced.url, baudrate=38400, timeout=0.05) as port:
        paced.chunks()
        port.send_break(0.01)
        assert wait_until(lambda: b"\x00" in b"".join(paced.raw), 2)   # the echo of it
        assert b"".join(paced.chunks()) == b"\x00"


def test_0xff_crosses_both_ways_as_telnet_data(served: Served) -> None:
    with serial.serial_for_url(served.url, baudrate=38400, timeout=0.05) as port:
        got = ask(port, b"\xff\xfe\r")
        assert got.startswith(b"\xff\xfe\r\n"), got      # the motor echoes what it read


def test_settings_a_port_server_answers(served: Served) -> None:
    with serial.serial_for_url(served.url, baudrate=38400, timeout=0.05) as port:
        for size in serial.Serial.BYTESIZES:             # each is acknowledged as set
            port.bytesize = size
        for stop in serial.Serial.STOPBITS:
            port.stopbits = stop
        for parity in serial.Serial.PARITIES:
            port.parity = parity
        port.rtscts = True
        port.xonxoff = False
        port.dtr = False
        port.rts = False
        port.reset_output_buffer()
        port.reset_input_buffer()
        assert (port.cts, port.dsr, port.cd, port.ri) == (True, True, True, False)
        port.bytesize, port.parity, port.stopbits = 8, "N", 1
        assert ask(port, b"?96.1\r") == b"?96.1\r\nPx.1=0\r\n"   # flow control holds nothing


def _raw(url: str) -> socket.socket:
    host, port = url.removeprefix("rfc2217://").split(":")
    sock = socket.create_connection((host, int(port)), timeout=2)
    sock.settimeout(0.3)
    return sock


def _read_all(sock: socket.socket) -> bytes:
    got = b""
    try:
        while chunk := sock.recv(4096):
            got += chunk
    except TimeoutError:
        pass
    return got


def _option(*body: int) -> bytes:
    return bytes([IAC, SB, COM_PORT, *body, IAC, SE])


@pytest.mark.parametrize("asked, answer", [
    (7, 8), (10, 11), (4, 6), (13, 14), (16, 16),   # DTR, RTS, break, inbound flow
])
def test_the_states_a_client_asks_for_are_answered(served: Served, asked: int,
                                                   answer: int) -> None:
    with _raw(served.url) as sock:
        _read_all(sock)                               # the server's own negotiation
        sock.sendall(_option(5, asked))
        assert _option(105, answer) in _read_all(sock)


@pytest.mark.parametrize("garbage", [
    _option(1, 0, 1),            # SET-BAUDRATE cut short
    _option(3, 99),              # a parity with no name
    _option(4, 9),               # a stop size with no name
    _option(10),                 # SET-LINESTATE-MASK without its value
    bytes([IAC, SB, IAC, SE]),   # an empty subnegotiation
    bytes([IAC, 0xF3]),          # a Telnet BREAK command
])
def test_malformed_options_are_ignored_and_the_data_after_them_arrives(
        served: Served, garbage: bytes) -> None:
    with _raw(served.url) as sock:
        _read_all(sock)
        sock.sendall(garbage + b"?96.1\r")
        assert _read_all(sock).endswith(b"?96.1\r\nPx.1=0\r\n")
        sock.sendall(_option(5, 7))                   # the manager still answers
        assert _option(105, 8) in _read_all(sock)


def test_several_clients_each_with_its_own_rate(paced: Served) -> None:
    with serial.serial_for_url(paced.url, baudrate=38400, timeout=0.05) as right, \
            serial.serial_for_url(paced.url, baudrate=9600, timeout=0.05) as wrong:
        right.reset_input_buffer()
        wrong.reset_input_buffer()
        heard = ask(right, b"?96.1\r")
        assert heard.endswith(b"Px.1=0\r\n"), heard
        time.sleep(0.2)
        assert b"Px.1" not in wrong.read(wrong.in_waiting or 1)


def test_a_silent_client_makes_room_without_a_word_when_every_place_is_taken() -> None:
    st = ServiceThread(Chain, lambda: [Rfc2217Transport(port=0, max_clients=1,
                                                        idle_timeout=0.0)]).start()
    try:
        url = f"rfc2217://127.0.0.1:{st.transports[0].info()['port']}"
        with _raw(url) as silent:
            negotiation = _read_all(silent)
            with serial.serial_for_url(url, baudrate=38400, timeout=0.05) as port:
                assert ask(port, b"?96.1\r") == b"?96.1\r\nPx.1=0\r\n"
                silent.settimeout(2)
                assert silent.recv(4096) == b""      # closed (end of stream), no words
            assert negotiation.startswith(bytes([IAC]))
    finally:
        st.stop()


# -- the tools over rfc2217:// ------------------------------------------------------------

def test_the_host_library_over_rfc2217(served: Served) -> None:
    with coolmuscle.connect(served.url) as motor:
        motor.write_param(37, 3)
        assert motor.read_param(37) == 3
        assert motor.get_position() == 0


def test_scan_finds_the_motors_rate_by_changing_the_clients(paced: Served) -> None:
    paced.execute("K20.1=2")                          # 19200 bit/s (ch. 3 K20 table)
    progress: list[str] = []
    result = scan(paced.url, progress=progress.append)
    assert result.baud == 19200
    assert result.lines() == ["ID1  K20=2 (19200 bit/s)  cm2  ID1 : CM2v3.10R.1 #0802A12345"]
    assert progress[:3] == ["trying 38400 bit/s", "trying 9600 bit/s", "trying 19200 bit/s"]
    assert paced.st.call(lambda: paced.st.chain.get_param(1, 20)) == 2   # queries only


# -- the command line -----------------------------------------------------------------------

def run_cli(args: list[str], stdin: str = "") -> tuple[int, str, str]:
    """``coolmuscle ARGS`` as a process: (exit status, stdout, stderr)."""
    done = subprocess.run([sys.executable, "-m", "coolmuscle", *args], env=child_env(),
                          input=stdin, capture_output=True, text=True, timeout=120)
    return done.returncode, done.stdout, done.stderr


@pytest.fixture
def cli_sim(tmp_path: Path) -> Iterator[ServedSim]:
    sim = ServedSim(tmp_path / "sim.log", "--pace", tcp=False, rfc2217=True)
    try:
        yield sim
    finally:
        sim.close()


def test_sim_serves_rfc2217_on_loopback(cli_sim: ServedSim) -> None:
    assert cli_sim.served["rfc2217"].startswith("127.0.0.1:"), cli_sim.banner
    assert list(cli_sim.served) == ["rfc2217"]        # no default TCP beside it
    with serial.serial_for_url(cli_sim.rfc2217_url, baudrate=38400, timeout=0.05) as port:
        assert ask(port, b"?96.1\r") == b"?96.1\r\nPx.1=0\r\n"


def test_term_over_rfc2217(cli_sim: ServedSim) -> None:
    code, out, err = run_cli(["term", cli_sim.rfc2217_url, "--timeout", "0.5"],
                             stdin="?96.1\n:quit\n")
    assert (code, out) == (0, "Px.1=0\n"), err


def test_scan_command_over_rfc2217(cli_sim: ServedSim) -> None:
    code, out, err = run_cli(["scan", cli_sim.rfc2217_url])
    assert (code, out) == (0, "ID1  K20=0 (38400 bit/s)  cm2  ID1 : CM2v3.10R.1 #0802A12345\n"), \
        err
    assert "at 38400 bit/s" in err


@pytest.mark.parametrize("value, message", [
    ("nope", "--rfc2217: bad TCP address 'nope': expected [HOST:]PORT"),
    ("70000", "--rfc2217: bad TCP port 70000 (0..65535)"),
])
def test_a_bad_address_is_one_line(value: str, message: str,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = cli(capsys, "sim", "--rfc2217", value, "--no-state")
    assert (code, out, err) == (2, "", f"coolmuscle: error: {message}\n")
