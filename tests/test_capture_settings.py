"""What ``coolmuscle capture`` finds out before the session (docs/user-guide.md
"coolmuscle capture"): the probe asks ``?85.1``, ``K20.1``, ``K23.1`` (ch. 3 K20, K23;
6.6 ?85) and nothing else, scans the K20 rates and K82 parities on a serial device
that does not answer, and the header says what it found.

The motor here is a fake serial port that understands only one rate and parity (what
a real motor set by K20/K82 does; a pty or a socket has no wire to show it): at any
other setting it hears garbage and answers garbage.
"""

from __future__ import annotations

import time
from datetime import UTC, datetime

import pytest

from coolmuscle.tools.capture import settings as settings_module
from coolmuscle.tools.capture.recording import header_lines
from coolmuscle.tools.capture.settings import LineSettings, probe

VERSION = "ID1 : CM2v3.10R.1 #0802A12345"


class WiredMotor:
    """A pyserial-like port to a motor set to ``rate`` and ``parity`` (K20, K82)."""

    def __init__(self, rate: int, parity: str, k20: int, k23: int) -> None:
        self.rate, self.wire_parity = rate, parity
        self.k20, self.k23 = k20, k23
        self.baudrate, self.parity, self.timeout = 38400, "N", 0.01
        self.heard: list[str] = []           # lines the motor understood
        self._line = bytearray()
        self._out = bytearray()

    @property
    def in_waiting(self) -> int:
        return len(self._out)

    def reset_input_buffer(self) -> None:
        self._out.clear()

    def read(self, size: int = 1) -> bytes:
        if not self._out:
            time.sleep(self.timeout)
            return b""
        data = bytes(self._out[:size])
        del self._out[:size]
        return data

    def write(self, data: bytes) -> int:
        if (self.baudrate, self.parity) != (self.rate, self.wire_parity):
            self._out += b"\xfe\x80" * len(data)          # framing errors both ways
            return len(data)
        for byte in data:
            if byte != 13:
                self._line.append(byte)
                continue
            line = self._line.decode()
            self._line.clear()
            self.heard.append(line)
            if not self.k23 & 8:
                self._out += line.encode() + b"\r\n"       # the echo (K23 function 8 off)
            reply = {"?85.1": VERSION, "K20.1": f"K20.1={self.k20}",
                     "K23.1": f"K23.1={self.k23}"}.get(line)
            if reply is not None:
                self._out += reply.encode() + b"\r\n"
        return len(data)


@pytest.fixture(autouse=True)
def quick(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(settings_module, "REPLY_TIMEOUT", 0.1)
    monkeypatch.setattr(settings_module, "QUIET", 0.02)


def test_a_serial_motor_at_another_rate_and_parity_is_found_and_only_asked() -> None:
    """K20=1 (9.6 kbps), K82=1 (even), K23=9 (reports, no echo): every rate and parity
    is tried until one answers; the motor heard only queries."""
    motor = WiredMotor(9600, "E", k20=1, k23=9)
    said: list[str] = []
    found = probe(motor, "/dev/ttyUSB0", LineSettings(), scan=True, say=said.append)
    assert found == LineSettings(baud=9600, parity="even", echo=False, k20=1, k23=9,
                                 firmware="cm2")
    assert (motor.baudrate, motor.parity) == (9600, "E")    # the port is left there
    assert motor.heard == ["", "?85.1", "K20.1", "K23.1"]   # a CR ends earlier garbage
    assert said == ["no answer at 38400 bit/s, parity none: trying the others"]


def test_echo_comes_from_k23_and_the_rate_from_k20() -> None:
    motor = WiredMotor(38400, "N", k20=0, k23=17)
    found = probe(motor, "socket://127.0.0.1:5150", LineSettings(), scan=True,
                  say=pytest.fail)
    assert found == LineSettings(baud=38400, parity="none", echo=True, k20=0, k23=17,
                                 firmware="cm2")
    assert motor.heard == ["?85.1", "K20.1", "K23.1"]


@pytest.mark.parametrize("url, scan", [("socket://127.0.0.1:5150", True),
                                       ("coolmuscle://", True), ("/dev/ttyUSB0", False)])
def test_no_scan_without_a_wire_or_with_the_rate_given(url: str, scan: bool) -> None:
    """A socket has no baud rate; ``--baud``/``--parity`` given: one try, then the
    settings as given with echo unknown, said in one line."""
    motor = WiredMotor(9600, "E", k20=1, k23=9)
    said: list[str] = []
    given = LineSettings(baud=38400, parity="none")
    assert probe(motor, url, given, scan=scan, say=said.append) == given
    assert motor.heard == [] and (motor.baudrate, motor.parity) == (38400, "N")
    assert len(said) == 1 and "did not answer ?85.1" in said[0]


def test_the_header_says_what_is_known() -> None:
    started = datetime(2026, 12, 3, 10, 0, 0, 123456, tzinfo=UTC)
    found = LineSettings(baud=9600, parity="even", echo=False, k20=1, k23=9, firmware="rt3")
    assert header_lines("/dev/ttyUSB0", found, started, motors=2, machine="../m 1.toml") == [
        "# coolmuscle capture: port=/dev/ttyUSB0 baud=9600 parity=even echo=off "
        "started=2026-12-03T10:00:00.123456Z k20=1 k23=9 motors=2",
        "# chain: motors=2 firmware=rt3 machine=../m%201.toml"]
    assert header_lines("socket://h:1", LineSettings(), started) == [
        "# coolmuscle capture: port=socket://h:1 baud=38400 parity=none echo=unknown "
        "started=2026-12-03T10:00:00.123456Z"]
