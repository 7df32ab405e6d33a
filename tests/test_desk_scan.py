"""``coolmuscle scan``: the probe is harmless at a wrong rate, the scan is bounded, and a
line with no motor, or a wrong ``--baud``, is one line and exit status 2."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator

import pytest

from cli_support import cli
from coolmuscle.chain.daisy import Chain
from coolmuscle.device.uart import as_read_at
from coolmuscle.frontends.transports.pty import PtyTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.tools.desk import NoMotorError, scan, scan_bound
from coolmuscle.tools.desk.linescan import probe_pieces

RATES = (9600, 19200, 38400, 57600, 115200, 230400)


def _cml_or_line_end(data: bytes) -> bool:
    return any(0x20 <= b <= 0x7E or b in (0x0A, 0x0D) for b in data)


@pytest.mark.parametrize("motor", range(1, 16))
def test_at_a_wrong_rate_a_motor_reads_no_cml_character_of_the_probe(motor: int) -> None:
    pieces = (b"\r", *probe_pieces(motor))
    assert b"".join(pieces[1:]) == f"?85.{motor}\r".encode()
    for sent in RATES:
        for read in RATES:
            if sent == read:
                continue
            for percent in (97, 100, 103):       # a rate off by up to 3 %
                for piece in pieces:
                    garbage = as_read_at(piece, sent * percent, read * 100)
                    assert not _cml_or_line_end(garbage), (sent, read, percent, piece)


def test_the_probe_sent_whole_could_free_the_motor() -> None:
    # why the pieces: at 9.6 kbps, "?85.1" + CR sent whole at 57.6 kbps reads ")",
    # motor free (2.1.2), run at the next CR
    assert as_read_at(b"?85.1\r", 57600, 9600) == b")"


def test_a_virtual_chain_answers_without_a_rate() -> None:
    result = scan("coolmuscle://?motors=3&mode=fast")
    assert result.baud is None and result.ids == (1, 2, 3)
    assert result.lines()[1] == "ID2  K20=0 (38400 bit/s)  cm2  ID2 : CM2v3.10R.1 #0802A12345"
    assert scan("coolmuscle://?motors=3&mode=fast", ids=(2, 5, 3)).ids == (2, 3)
    rt3 = scan("coolmuscle://?firmware=rt3&mode=fast").motors[0]
    assert (rt3.firmware, rt3.title) == ("rt3", "ID1 : CM1v3.00R.1 #0000A00000")


@pytest.fixture
def silent_pty() -> Iterator[str]:
    """A pty with nothing behind it."""
    master, slave = os.openpty()
    try:
        yield os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


def test_nothing_answers_within_the_bound(silent_pty: str) -> None:
    started = time.monotonic()
    with pytest.raises(NoMotorError) as caught:
        scan(silent_pty, timeout=0.05)
    took = time.monotonic() - started
    assert str(caught.value) == (
        f"no motor answers on {silent_pty} at 38400, 9600, 19200, 57600, 115200 or 230400 "
        "bit/s (?85.1 within 0.05 s at each); check the cable, the power and the port")
    assert took <= scan_bound(RATES, range(1, 16), 0.05) + 0.5


def test_nothing_answers_is_one_line_and_exit_status_2(
        silent_pty: str, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = cli(capsys, "scan", silent_pty, "--timeout", "0.05", "--baud", "38400")
    assert (code, out) == (2, "")
    assert err == (f"coolmuscle: error: no motor answers on {silent_pty} at 38400 bit/s "
                   "(?85.1 within 0.05 s); a wrong --baud? (without it every K20 rate is "
                   "tried)\n")


@pytest.fixture
def paced_pty() -> Iterator[str]:
    st_ = ServiceThread(lambda: Chain(pacing=True), lambda: [PtyTransport()]).start()
    try:
        yield str(st_.transports[0].info()["path"])
    finally:
        st_.stop()


def test_a_wrong_baud_is_one_line_and_exit_status_2(
        paced_pty: str, capsys: pytest.CaptureFixture[str]) -> None:
    for command in (["scan", paced_pty], ["backup", paced_pty, "-o", os.devnull, "--force"]):
        code, out, err = cli(capsys, *command, "--baud", "9600")
        assert (code, out) == (2, "")
        assert err.startswith(f"coolmuscle: error: no motor answers on {paced_pty} at 9600 "
                              "bit/s (?85.1 within 0.3 s); a wrong --baud?")
        assert err.count("\n") == 1
    code, out, _err = cli(capsys, "scan", paced_pty, "--baud", "9600", "--baud", "38400")
    assert (code, out) == (0, "ID1  K20=0 (38400 bit/s)  cm2  ID1 : CM2v3.10R.1 #0802A12345\n")


@pytest.mark.parametrize("option, value, message", [
    ("--baud", "12345", "--baud 12345 is not a K20 rate (ch. 3 K20: 9600, 19200, 38400, "
                        "57600, 115200, 230400)"),
    ("--ids", "0-3", "--ids 0-3: motor IDs are 1..15"),
    ("--ids", "one", "--ids takes IDs and ranges such as 1-3,5, not 'one'"),
])
def test_bad_options(option: str, value: str, message: str,
                     capsys: pytest.CaptureFixture[str]) -> None:
    code, _out, err = cli(capsys, "scan", "coolmuscle://?mode=fast", option, value)
    assert (code, err) == (2, f"coolmuscle: error: {message}\n")


class _OtherTitle:
    """A port whose motor answers ``?85.1`` with a title in a form 6.6 does not show and
    ``K20.1`` with 0; nothing else (a socket: no wire)."""

    def __init__(self) -> None:
        self.timeout = 0.05
        self._out = bytearray()

    @property
    def in_waiting(self) -> int:
        return len(self._out)

    def write(self, data: bytes) -> int:
        answers = {b"?85.1\r": b"ID1 : Motor X v9 (custom)\r\n", b"K20.1\r": b"K20.1=0\r\n"}
        self._out += answers.get(data, b"")
        return len(data)

    def read(self, size: int = 1) -> bytes:
        data, self._out[:] = bytes(self._out[:size]), self._out[size:]
        if not data:
            time.sleep(self.timeout)
        return data

    def reset_input_buffer(self) -> None:
        self._out.clear()


def test_a_title_of_another_form_is_shown_with_an_unknown_firmware() -> None:
    from coolmuscle.tools.desk.linescan import scan_port
    result = scan_port(_OtherTitle(), "socket://bench:4001", timeout=0.05)
    assert result.lines() == ["ID1  K20=0 (38400 bit/s)  ?  ID1 : Motor X v9 (custom)"]
