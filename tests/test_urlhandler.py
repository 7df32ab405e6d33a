"""pyserial ``coolmuscle://`` URL handler: options, realtime and fast modes, threads, errors."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import serial
from serial.serialutil import PortNotOpenError, SerialException

import coolmuscle
from coolmuscle.frontends.urlhandler import protocol_coolmuscle as handler
from coolmuscle.sim.kernel import NS_PER_S, seconds
from fakes import ROUNDTRIP, FakeChain, fake_factory, play_over_serial

coolmuscle.register_url_handler()      # pyserial's protocol_handler_packages (once)


@pytest.fixture
def fake(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[dict[str, Any]]]:
    """Replace the chain behind coolmuscle:// by FakeChain; yields the factory calls."""
    calls: list[dict[str, Any]] = []
    make = fake_factory(move_time=0.2)

    def factory(kernel: Any, motors: int, **options: Any) -> FakeChain:
        calls.append({"motors": motors, **options})
        return make(kernel, motors, **options)
    monkeypatch.setattr(handler, "chain_factory", factory)
    yield calls


def test_register_appends_the_package_to_pyserials_list_once() -> None:
    coolmuscle.register_url_handler()
    assert serial.protocol_handler_packages[0] == "serial.urlhandler"   # pyserial's own first
    assert serial.protocol_handler_packages.count("coolmuscle.frontends.urlhandler") == 1


#: A fresh interpreter: the scheme before and after registering, and through connect().
FRESH = r"""
import json, sys, serial, coolmuscle
import coolmuscle.frontends.urlhandler
out = {"listed": list(serial.protocol_handler_packages)}
try:
    serial.serial_for_url("coolmuscle://?mode=fast", timeout=0.5)
except ValueError as exc:
    out["before"] = str(exc)
if sys.argv[1] == "register":
    coolmuscle.register_url_handler()
    with serial.serial_for_url("coolmuscle://?mode=fast", timeout=0.5) as port:
        port.write(b"?96.1\r")
        out["echo"] = port.read_until(b"\r\n").decode()
else:
    with coolmuscle.connect("coolmuscle://?mode=fast") as m:
        out["echo"] = m.id
out["after"] = list(serial.protocol_handler_packages)
json.dump(out, sys.stdout)
"""


@pytest.mark.parametrize("how", ["register", "connect"])
def test_the_scheme_is_known_once_registered_not_on_import(how: str) -> None:
    """Importing coolmuscle leaves pyserial's list alone (``coolmuscle://`` is an unknown
    protocol); ``register_url_handler()`` or a ``connect("coolmuscle://...")`` adds it."""
    import json
    import os
    import subprocess
    import sys
    done = subprocess.run([sys.executable, "-c", FRESH, how], capture_output=True, text=True,
                          env=dict(os.environ), timeout=60, check=True)
    out = json.loads(done.stdout)
    assert out["listed"] == ["serial.urlhandler"]
    assert out["before"] == "invalid URL, protocol 'coolmuscle' not known"
    assert out["after"] == ["serial.urlhandler", "coolmuscle.frontends.urlhandler"]
    assert out["echo"] == ("?96.1\r\n" if how == "register" else 1)


def test_default_chain_answers_with_the_real_host_line() -> None:
    """The real Chain (placeholder or model) behind the URL: at least the echo comes back."""
    with serial.serial_for_url("coolmuscle://?mode=fast", timeout=0.5) as port:
        port.write(b"?96.1\r")
        assert port.read_until(b"\r\n") == b"?96.1\r\n"


@pytest.mark.parametrize("mode", ["realtime", "fast"])
def test_transcript_in_both_modes(fake: list[dict[str, Any]], mode: str) -> None:
    with serial.serial_for_url(f"coolmuscle://?mode={mode}", timeout=1) as port:
        start = time.monotonic()
        play_over_serial(port, ROUNDTRIP)
        elapsed = time.monotonic() - start
    if mode == "fast":
        assert elapsed < 0.5          # the 0.2 s move took no wall time
    else:
        assert elapsed >= 0.15        # it took (about) its real time


def test_options_reach_the_chain(fake: list[dict[str, Any]], tmp_path: Path) -> None:
    state = tmp_path / "state"
    url = f"coolmuscle://?motors=3&firmware=RT3&state={state}&pacing=on&mode=fast"
    with serial.serial_for_url(url) as port:
        assert port.chain.motor_ids == (1, 2, 3)
    assert fake == [{"motors": 3, "firmware": "rt3", "state_dir": state, "pacing": True}]
    assert state.is_dir()


@pytest.mark.parametrize("url, reason", [
    ("coolmuscle://?bogus=1", "unknown option: 'bogus'"),
    ("coolmuscle://?motors=16", "motors must be 1..15"),
    ("coolmuscle://?motors=x", "motors must be 1..15"),
    ("coolmuscle://?firmware=cm9", "unknown firmware"),
    ("coolmuscle://?mode=slow", "unknown mode"),
    ("coolmuscle://?pacing=maybe", "pacing must be on or off"),
    ("coolmuscle://?scale=0", "scale must be a positive number"),
    ("coolmuscle://host:1", "unexpected 'host:1'"),
])
def test_bad_urls_show_the_expected_form(url: str, reason: str) -> None:
    with pytest.raises(SerialException) as info:
        serial.serial_for_url(url)
    assert handler.URL_FORMAT in str(info.value) and reason in str(info.value)


def test_fast_read_timeout_advances_virtual_time_exactly(fake: list[dict[str, Any]]) -> None:
    with serial.serial_for_url("coolmuscle://?mode=fast", timeout=2.5) as port:
        assert port.read(1) == b""
        assert port.kernel.now == seconds(2.5)
        port.write(b"^.1\r")
        assert port.read(5) == b"^.1\r\n"           # already there: no time passes
        assert port.kernel.now == seconds(2.5)
        assert port.read_until(b"Ux.1=8\r\n") == b"Ux.1=8\r\n"
        assert port.kernel.now == seconds(2.7)      # stopped as soon as the bytes came


def test_fast_mode_is_deterministic(fake: list[dict[str, Any]]) -> None:
    runs = []
    for _ in range(2):
        with serial.serial_for_url("coolmuscle://?mode=fast&pacing=on", timeout=0.01) as port:
            port.write(b"?96.1\r^.1\r")
            got = []
            for _ in range(40):
                got.append((port.kernel.now, port.read(3)))
            runs.append(got)
    assert runs[0] == runs[1]
    assert any(data for _, data in runs[0])


def test_nonblocking_read_and_in_waiting(fake: list[dict[str, Any]]) -> None:
    with serial.serial_for_url("coolmuscle://", timeout=0) as port:
        assert port.read(10) == b""
        port.write(b"?96.1\r")
        assert port.in_waiting == len(b"?96.1\r\nPx.1=1\r\n")
        port.reset_input_buffer()
        assert port.in_waiting == 0 and port.out_waiting == 0


def test_realtime_scale_speeds_up_virtual_time(fake: list[dict[str, Any]]) -> None:
    with serial.serial_for_url("coolmuscle://?scale=20", timeout=2) as port:
        start = time.monotonic()
        port.write(b"^.1\r")
        assert port.read_until(b"Ux.1=8\r\n").endswith(b"Ux.1=8\r\n")
        assert time.monotonic() - start < 0.15      # 0.2 s of motor time at 20x


def test_a_blocking_reader_thread_is_woken_by_a_writer(fake: list[dict[str, Any]]) -> None:
    for mode in ("realtime", "fast"):
        with serial.serial_for_url(f"coolmuscle://?mode={mode}", timeout=None) as port:
            got: list[bytes] = []
            # the thread is joined in this iteration (B023)
            reader = threading.Thread(target=lambda: got.append(port.read(15)))  # noqa: B023
            reader.start()
            time.sleep(0.05)
            port.write(b"?96.1\r")
            reader.join(5)
            assert got == [b"?96.1\r\nPx.1=1\r\n"], mode


def test_cancel_read_releases_a_blocked_reader(fake: list[dict[str, Any]]) -> None:
    with serial.serial_for_url("coolmuscle://", timeout=None) as port:
        got: list[bytes] = []
        reader = threading.Thread(target=lambda: got.append(port.read(1)))
        reader.start()
        time.sleep(0.05)
        port.cancel_read()
        reader.join(5)
        assert got == [b""]


def test_model_failure_is_not_a_serial_error(fake: list[dict[str, Any]]) -> None:
    with serial.serial_for_url("coolmuscle://?mode=fast", timeout=0.1) as port:
        assert port.write(b"boom\r") == 5
        assert port.read(100) == b"boom\r\n"


def test_close_closes_the_chain_and_the_port(fake: list[dict[str, Any]]) -> None:
    port = serial.serial_for_url("coolmuscle://", timeout=0)
    chain = port.chain
    port.close()
    assert chain.closed
    with pytest.raises(PortNotOpenError):
        port.read(1)
    with pytest.raises(PortNotOpenError):
        port.write(b"x")


def test_status_lines_and_settings(fake: list[dict[str, Any]]) -> None:
    with serial.serial_for_url("coolmuscle://", baudrate=38400) as port:
        assert port.cts and port.dsr and not port.ri and not port.cd
        port.baudrate = 9600
        port.rts = False
        port.dtr = False
        port.send_break(0.001)
        port.flush()
    with pytest.raises(ValueError):
        serial.serial_for_url("coolmuscle://", baudrate=-5)


def test_pacing_takes_wire_time_in_virtual_time(fake: list[dict[str, Any]]) -> None:
    with serial.serial_for_url("coolmuscle://?mode=fast&pacing=on", timeout=1) as port:
        port.write(b"?96.1\r")
        assert port.read_until(b"Px.1=1\r\n").endswith(b"Px.1=1\r\n")
        # 6 bytes in, 7 echoed, 8 replied at 38.4 kbps (10 bits a byte)
        assert port.kernel.now == 21 * (10 * NS_PER_S // 38400)


def test_a_failing_line_does_not_swallow_the_lines_after_it(fake: list[dict[str, Any]]) -> None:
    with serial.serial_for_url("coolmuscle://?mode=fast", timeout=0.1) as port:
        port.write(b"boom\r?96.1\r")
        assert port.read(100) == b"boom\r\n?96.1\r\nPx.1=1\r\n"
