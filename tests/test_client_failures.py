"""Failure paths of the host library: silence, garbage, a lost connection, alarms.

* a motor that stops answering in the middle of a wait gives a timeout within its
  timeout (a TCP proxy that stops forwarding, like a pulled cable; also behind socat);
* a garbled reply is reported (event, log, exception text) and never hangs the client;
* a connection that drops raises :class:`TransportError` at once;
* an alarm in polling mode (K23 without 1) surfaces as :class:`AlarmError` too;
* a refused value is a :class:`CoolMuscleError` that is also a ``ValueError``; a
  ``socket://`` URL without a port names the form it needs.
"""

from __future__ import annotations

import logging
import select
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import coolmuscle
from client_targets import InProcess, Tcp
from coolmuscle.client import MotorEvent, connect
from coolmuscle.errors import (
    AlarmError,
    CoolMuscleError,
    CoolMuscleTimeout,
    InvalidArgumentError,
    ProtocolError,
    TransportError,
)
from fixtures import ROOT, run_coolmuscle, wait_until


class FreezingProxy:
    """A TCP relay to ``port`` that can stop forwarding without closing anything."""

    def __init__(self, port: int) -> None:
        self.target = port
        self.frozen = threading.Event()
        self.closed = threading.Event()
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        self.server.settimeout(0.1)
        while not self.closed.is_set():
            try:
                client, _ = self.server.accept()
            except OSError:
                continue
            upstream = socket.create_connection(("127.0.0.1", self.target))
            threading.Thread(target=self._pump, args=(client, upstream), daemon=True).start()

    def _pump(self, a: socket.socket, b: socket.socket) -> None:
        with a, b:
            while not self.closed.is_set():
                ready, _, _ = select.select([a, b], [], [], 0.05)
                if self.frozen.is_set():
                    continue                  # bytes stay where they are: silence
                for sock in ready:
                    data = sock.recv(65536)
                    if not data:
                        return
                    (b if sock is a else a).sendall(data)

    def close(self) -> None:
        self.closed.set()
        self.server.close()


@pytest.fixture
def served() -> Iterator[Tcp]:
    target = Tcp()
    yield target
    target.close()


@pytest.fixture
def proxy(served: Tcp) -> Iterator[FreezingProxy]:
    relay = FreezingProxy(served.port)
    yield relay
    relay.close()


def test_a_motor_that_stops_answering_mid_wait_times_out_in_time(proxy: FreezingProxy) -> None:
    with connect(f"socket://127.0.0.1:{proxy.port}") as m:
        m.move_to(200000, speed=10, accel=100)      # 5 s of motion at 4x: never ends here
        threading.Timer(0.3, proxy.frozen.set).start()
        start = time.monotonic()
        with pytest.raises(CoolMuscleTimeout, match="not in position within 1.5 s"):
            m.wait_in_position(timeout=1.5)
        assert 1.5 <= time.monotonic() - start < 1.8
        start = time.monotonic()
        with pytest.raises(CoolMuscleTimeout, match=r"no Px\.1= reply"):
            m.get_position()                          # each reply has its own bound
        assert 1.0 <= time.monotonic() - start < 1.3


def test_silence_behind_a_socat_pty_times_out_in_time(proxy: FreezingProxy,
                                                      tmp_path: Path) -> None:
    link = tmp_path / "pty"
    socat = subprocess.Popen(["socat", f"PTY,link={link},raw,echo=0",
                              f"TCP:127.0.0.1:{proxy.port}"])
    try:
        assert wait_until(link.exists, 5, 0.01), "socat did not create its pty"
        with connect(str(link), timeout=0.5) as m:
            m.write_param(23, 0)                      # polling mode this time
            m.move_to(200000, speed=10, accel=100)
            proxy.frozen.set()
            start = time.monotonic()
            with pytest.raises(CoolMuscleTimeout):
                m.wait_in_position(timeout=1.0)
            assert time.monotonic() - start < 1.3
    finally:
        socat.terminate()
        socat.wait(5)


def test_silence_in_virtual_time_is_a_virtual_timeout() -> None:
    """On coolmuscle://?mode=fast the timeout is the motor's seconds: no wall time."""
    target = InProcess()
    with target.open() as m:
        m.move_to(1000000, speed=1, accel=1)          # ~100 s of motion
        start, virtual = time.monotonic(), m.port.kernel.now
        with pytest.raises(CoolMuscleTimeout):
            m.wait_in_position(timeout=20)
        assert (m.port.kernel.now - virtual) / 1e9 == pytest.approx(20, abs=0.3)
        assert time.monotonic() - start < 2


class ScriptedPort:
    """A pyserial-like port whose motor answers from a script (request -> bytes)."""

    def __init__(self, answers: dict[bytes, bytes]) -> None:
        self.answers = answers
        self.timeout: float | None = 1.0
        self.rx = bytearray()
        self.written = bytearray()

    def write(self, data: bytes) -> int:
        self.written += data
        for line in data.split(b"\r"):
            if line:
                self.rx += line + b"\r\n" + self.answers.get(line, b"")
        return len(data)

    def read(self, size: int = 1) -> bytes:
        if not self.rx and self.timeout:
            time.sleep(min(self.timeout, 0.05))
        data = bytes(self.rx[:size])
        del self.rx[:size]
        return data

    @property
    def in_waiting(self) -> int:
        return len(self.rx)

    def reset_input_buffer(self) -> None:
        self.rx.clear()

    def close(self) -> None:
        pass


def test_a_garbled_value_is_a_protocol_error() -> None:
    port = ScriptedPort({b"?96.1": b"Px.1=12a4\r\n", b"?70.1": b"IN.1=zz\r\n"})
    m = connect(port)
    with pytest.raises(ProtocolError, match="Px.1=12a4"):
        m.get_position()
    with pytest.raises(ProtocolError, match="IN.1=zz"):
        m.get_inputs()


def test_unreadable_bytes_are_reported_and_end_in_a_timeout(caplog: Any) -> None:
    port = ScriptedPort({b"?96.1": b"\xff\xfe\x00garbage\r\n"})
    m = connect(port, timeout=0.4)
    seen: list[MotorEvent] = []
    m.subscribe(seen.append)
    start = time.monotonic()
    with caplog.at_level(logging.WARNING, logger="coolmuscle.client.driver"):
        with pytest.raises(CoolMuscleTimeout, match="unreadable line"):
            m.get_position()
    assert time.monotonic() - start < 0.8
    assert [e.kind for e in seen] == ["garbled"]
    assert "unreadable line from the motor" in caplog.text
    port.answers[b"?96.1"] = b"Px.1=5\r\n"
    assert m.get_position() == 5                      # and the connection goes on


def test_endless_garbage_without_line_ends_never_hangs() -> None:
    class Noise(ScriptedPort):
        def read(self, size: int = 1) -> bytes:
            return b"\x55" * size

        @property
        def in_waiting(self) -> int:
            return 1000

    m = connect(Noise({}), timeout=0.3)
    start = time.monotonic()
    with pytest.raises(CoolMuscleTimeout):
        m.get_position()
    assert time.monotonic() - start < 0.6


def test_a_dropped_connection_is_a_transport_error(served: Tcp) -> None:
    m = connect(served.url)
    assert m.position == 0
    served.close()
    with pytest.raises(TransportError):
        for _ in range(3):                            # the first write may still succeed
            m.get_position()
    m.close()


def test_an_alarm_while_polling_is_an_alarm_error() -> None:
    target = InProcess()
    with target.open() as m:
        m.write_param(23, 0)
        m.move_to(100000, speed=20, accel=100)
        target.inject(lambda chain: chain.motors[1].raise_alarm(4), after=0.5)
        with pytest.raises(AlarmError) as caught:
            m.wait_in_position(timeout=5)
        assert caught.value.status == 4 and "Ux.1=4" in str(caught.value)


def test_connect_to_nothing_is_a_transport_error(closed_port: int) -> None:
    with pytest.raises(TransportError, match="cannot open"):
        connect(f"socket://127.0.0.1:{closed_port}")
    with pytest.raises(TransportError):
        connect("/dev/does-not-exist")


# -- the exception tree and bad URLs -----------------------------------------------------
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


def test_socket_url_without_a_port_names_the_form() -> None:
    with pytest.raises(TransportError, match=r"socket://HOST:PORT"):
        coolmuscle.connect("socket://127.0.0.1")
    done = run_coolmuscle("upload", str(ROOT / "examples" / "2.1-operation.cml"), "--port",
                          "socket://127.0.0.1")
    assert done.returncode == 1 and "socket://HOST:PORT" in done.stderr + done.stdout
    assert "NoneType" not in done.stderr + done.stdout
