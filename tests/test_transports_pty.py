"""Pseudo-terminal transport: pyserial on the pty, stable link, unread output, socat peers."""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import serial

from coolmuscle.errors import TransportError
from coolmuscle.frontends.transports.pty import PtyTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport
from fakes import ROUNDTRIP, fake_factory, play_over_serial
from fixtures import wait_until

Starter = Callable[..., ServiceThread]
needs_socat = pytest.mark.skipif(shutil.which("socat") is None, reason="socat is not installed")


@pytest.fixture
def start_pty() -> Iterator[Starter]:
    started: list[ServiceThread] = []

    def start(**pty_options: Any) -> ServiceThread:
        st_ = ServiceThread(fake_factory(move_time=0.2),
                            lambda: [PtyTransport(**pty_options)]).start()
        started.append(st_)
        return st_
    yield start
    for st_ in started:
        st_.stop()


def pty_path(st_: ServiceThread) -> str:
    path = st_.transports[0].info()["path"]
    assert path and path.startswith("/dev/")
    return path


def test_pyserial_opens_the_pty_and_plays_the_transcript(start_pty: Starter) -> None:
    st_ = start_pty()
    port = serial.Serial(pty_path(st_), baudrate=38400, timeout=1)
    try:
        play_over_serial(port, ROUNDTRIP)
    finally:
        port.close()


def test_port_survives_a_client_closing_and_reopening(start_pty: Starter) -> None:
    st_ = start_pty()
    for expected in (b"Px.1=1\r\n", b"Px.1=2\r\n"):
        with serial.Serial(pty_path(st_), timeout=2) as port:
            port.write(b"?96.1\r")
            assert port.read_until(expected) == b"?96.1\r\n" + expected


def test_link_points_at_the_pty_and_is_removed_on_close(tmp_path: Path) -> None:
    link = tmp_path / "coolmuscle-port"
    link.symlink_to("/nonexistent")          # a stale link from an earlier run is replaced
    st_ = ServiceThread(fake_factory(), lambda: [PtyTransport(link)]).start()
    try:
        assert os.readlink(link) == pty_path(st_)
        assert st_.transports[0].describe() == f"pty: {link} -> {pty_path(st_)}"
        with serial.Serial(str(link), timeout=2) as port:
            port.write(b"?96.1\r")
            assert port.read_until(b"Px.1=1\r\n").endswith(b"Px.1=1\r\n")
    finally:
        st_.stop()
    assert not link.exists() and not link.is_symlink()


def test_link_never_replaces_a_regular_file(tmp_path: Path) -> None:
    precious = tmp_path / "precious"
    precious.write_text("keep me")
    with pytest.raises(TransportError, match="not a symlink"):
        ServiceThread(fake_factory(), lambda: [PtyTransport(precious)]).start()
    assert precious.read_text() == "keep me"


def test_unread_output_is_bounded_and_the_port_still_works(start_pty: Starter) -> None:
    st_ = start_pty(max_buffer=8192)
    transport = st_.transports[0]
    for _ in range(200):                     # ~200 KB that nobody reads
        st_.call(st_.chain.host_line.send_line, "x" * 1000)
    assert transport.bytes_discarded > 0
    with serial.Serial(pty_path(st_), timeout=2) as port:
        port.reset_input_buffer()
        time.sleep(0.05)
        port.reset_input_buffer()            # what was still pending in our buffer
        port.write(b"?96.1\r")
        assert port.read_until(b"Px.1=1\r\n").endswith(b"?96.1\r\nPx.1=1\r\n")


@pytest.mark.peer
@needs_socat
def test_socat_as_an_independent_peer_on_the_pty(start_pty: Starter) -> None:
    st_ = start_pty()
    out = subprocess.run(["socat", "-t", "1", "-", f"{pty_path(st_)},raw,echo=0"],
                         input=b"?96.1\rS.1=100\r", capture_output=True, timeout=10)
    assert out.stdout == b"?96.1\r\nPx.1=1\r\nS.1=100\r\n"


@pytest.mark.peer
@needs_socat
def test_socat_as_an_independent_peer_over_tcp() -> None:
    st_ = ServiceThread(fake_factory(move_time=0.2), lambda: [TcpTransport(port=0)]).start()
    try:
        port = st_.transports[0].info()["port"]
        out = subprocess.run(["socat", "-t", "1", "-", f"TCP:127.0.0.1:{port}"],
                             input=b"?96.1\r^.1\r", capture_output=True, timeout=10)
        assert out.stdout == b"?96.1\r\nPx.1=1\r\n^.1\r\n"
    finally:
        st_.stop()


@pytest.mark.peer
@needs_socat
def test_socat_pty_pair_bridged_to_tcp(tmp_path: Path) -> None:
    """socat makes its own pty and bridges it to the TCP server: pyserial on socat's pty."""
    st_ = ServiceThread(fake_factory(move_time=0.2), lambda: [TcpTransport(port=0)]).start()
    link = tmp_path / "socat-pty"
    port = st_.transports[0].info()["port"]
    proc = subprocess.Popen(["socat", f"PTY,link={link},raw,echo=0", f"TCP:127.0.0.1:{port}"])
    try:
        assert wait_until(link.exists), "socat did not create its pty"
        with serial.Serial(str(link), timeout=1) as ser:
            play_over_serial(ser, ROUNDTRIP)
    finally:
        proc.terminate()
        proc.wait(5)
        st_.stop()
