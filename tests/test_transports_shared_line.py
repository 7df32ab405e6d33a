"""The motor's one host line shared by several clients.

Each client's lines are assembled apart and run whole, in turn with the others
(docs/reliability.md "fairness"); an upload ``B#.n`` (cml-users-guide.txt 2.2.2)
belongs to the client that opened it and ends with it; only a client that does
not read is dropped.  Real chain, real sockets on loopback, a real pty.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator

import pytest
import serial

from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.transports.pty import PtyTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport
from fixtures import wait_until
from load_support import Flood, round_trip
from modbus_support import Wire, frame

MANUAL = {"K78_1": 100, "K79_1": 200, "K80_1": 300, "K81_1": 1}


@pytest.fixture
def served() -> Iterator[ServiceThread]:
    st_ = ServiceThread(lambda: Chain(motors=2),
                        lambda: [TcpTransport(port=0), PtyTransport()]).start()
    yield st_
    st_.stop()


def connect(st_: ServiceThread) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", st_.transports[0].info()["port"]), timeout=10)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return sock


def read_until(sock: socket.socket, marker: bytes, count: int = 1,
               timeout: float = 10.0) -> bytes:
    data = b""
    deadline = time.monotonic() + timeout
    while data.count(marker) < count:
        remaining = deadline - time.monotonic()
        assert remaining > 0, f"timed out waiting for {marker!r} x{count}; got {data[-300:]!r}"
        sock.settimeout(remaining)
        chunk = sock.recv(1 << 16)
        assert chunk, f"connection closed; got {data[-300:]!r}"
        data += chunk
    return data


def wait_clients(st_: ServiceThread, n: int) -> None:
    assert wait_until(lambda: st_.transports[0].clients >= n, 5, 0.01), "clients not connected"


# -- item 1: a client is dropped only for its own failure to read --------------------
def test_one_write_of_600_listings_drops_no_reading_client(served: ServiceThread) -> None:
    """600 ``?P1.1`` (1.8 KB of reply each, over 1 MB) in one 3.6 KB write."""
    a, b = connect(served), connect(served)
    wait_clients(served, 2)
    got: dict[str, bytes] = {}

    def reader(name: str, sock: socket.socket) -> None:
        got[name] = read_until(sock, b"P197.1=", 600, timeout=60)
    threads = [threading.Thread(target=reader, args=(n, s)) for n, s in (("a", a), ("b", b))]
    for t in threads:
        t.start()
    a.sendall(b"?P1.1\r" * 600)
    for t in threads:
        t.join(70)
    assert served.transports[0].dropped_clients == 0
    assert got["a"].count(b"P197.1=") == got["b"].count(b"P197.1=") == 600


# -- item 2: per-client line assembly and fair turns -------------------------------
def test_a_partial_line_with_trickled_spaces_does_not_starve_another_client(
        served: ServiceThread) -> None:
    a, b = connect(served), connect(served)
    wait_clients(served, 2)
    a.sendall(b"?96.1")
    stop = threading.Event()

    def trickle() -> None:
        while not stop.wait(0.2):
            a.sendall(b" ")
    thread = threading.Thread(target=trickle)
    thread.start()
    try:
        time.sleep(0.3)
        start = time.monotonic()
        b.sendall(b"?99.1\r")
        read_until(b, b"Ux.1=", timeout=5)
        assert time.monotonic() - start < 1.0
    finally:
        stop.set()
        thread.join()


def test_a_flooding_client_does_not_slow_another_clients_round_trip(
        served: ServiceThread) -> None:
    with Flood(connect(served)), connect(served) as probe:
        wait_clients(served, 2)
        time.sleep(0.3)
        trips = sorted(round_trip(probe, b"?96.2\r", b"Px.2=") for _ in range(10))
    assert trips[-2] < 0.5, trips


def test_a_tcp_half_line_and_a_pty_line_are_never_one_line(served: ServiceThread) -> None:
    a = connect(served)
    wait_clients(served, 1)
    a.sendall(b"P1.1=12")
    time.sleep(0.1)
    pty = serial.Serial(served.transports[1].info()["path"], timeout=5)
    try:
        pty.write(b"?96.1\r")
        assert pty.read_until(b"Px.1=0\r\n").endswith(b"Px.1=0\r\n")
        a.sendall(b"\r")
        assert wait_until(lambda: served.call(lambda: served.chain.get_register(1, "P", 1))
                          == 12), "P1.1=12 was not run as its own line"
    finally:
        pty.close()


def test_each_senders_echo_is_its_own_whole_line_on_tcp_and_on_the_pty(
        served: ServiceThread) -> None:
    """A TCP client sends ``P1.1=12`` without its line end, a pty
    client ``?96.1\\r``, the TCP client finishes with ``3\\r``.  The lines ran apart, but
    both received ``P1.1=12?96.1\\r\\n``, the reply and a stray ``3\\r\\n``.  The echo is
    part of the motor's answer to its sender's line (ch. 3 K23 8): with several hosts
    connected each line's echo goes out whole at its line end, before its reply; every
    host sees the same bytes."""
    pty = serial.Serial(served.transports[1].info()["path"], timeout=5)
    a = connect(served)
    wait_clients(served, 1)
    try:
        a.sendall(b"P1.1=12")
        time.sleep(0.1)                      # the half line is in (the order makes no odds)
        pty.write(b"?96.1\r")
        seen_by_pty = pty.read_until(b"Px.1=0\r\n")
        a.sendall(b"3\r")
        seen_by_pty += pty.read_until(b"P1.1=123\r\n")
        want = b"?96.1\r\nPx.1=0\r\nP1.1=123\r\n"
        assert seen_by_pty == want
        assert read_until(a, b"P1.1=123\r\n") == want
        pty.timeout = 0.3                    # and nothing after it (the stray "3\r\n")
        assert pty.read(64) == b""
        a.settimeout(0.3)
        with pytest.raises(TimeoutError):
            a.recv(64)
        assert served.call(lambda: served.chain.get_register(1, "P", 1)) == 123
    finally:
        a.close()
        pty.close()


def test_a_host_alone_sees_its_echo_as_it_types_and_a_cut_one_again_whole(
        served: ServiceThread) -> None:
    """A TCP client alone (the pty of the fixture is a host too, so a second server with
    TCP only): ``?9`` is echoed at once.  A second client joins and ends a line while
    the first one's typed ``?9`` is out: that ``?9`` is ended with the delimiter, the
    second line follows whole, and the first line's echo comes again whole at its end."""
    alone = ServiceThread(lambda: Chain(), lambda: [TcpTransport(port=0)]).start()
    try:
        a = connect(alone)
        wait_clients(alone, 1)
        a.sendall(b"?9")
        assert read_until(a, b"?9") == b"?9"
        b = connect(alone)
        wait_clients(alone, 2)
        b.sendall(b"?96.1\r")
        assert read_until(b, b"Px.1=0\r\n") == b"\r\n?96.1\r\nPx.1=0\r\n"
        a.sendall(b"6.1\r")
        want = b"\r\n?96.1\r\nPx.1=0\r\n?96.1\r\nPx.1=0\r\n"     # after its "?9"
        assert read_until(a, b"Px.1=0\r\n", count=2) == want
        assert read_until(b, b"Px.1=0\r\n") == b"?96.1\r\nPx.1=0\r\n"
        a.close()
        b.close()
    finally:
        alone.stop()


# -- item 3: a bank upload belongs to the client that opened it ---------------------
def test_an_upload_left_open_by_a_departed_client_takes_no_other_line(
        served: ServiceThread) -> None:
    a, b = connect(served), connect(served)
    wait_clients(served, 2)
    a.sendall(b"B1.1\r")
    read_until(a, b"B1.1\r\n")
    a.close()
    time.sleep(0.1)
    b.sendall(b"?96.1\r")
    assert b"Px.1=0" in read_until(b, b"Px.1=", timeout=3)
    assert served.call(lambda: served.chain.motors[1].banks.listing(False, 1)) in (None, [])


def test_an_open_upload_takes_only_its_owners_lines(served: ServiceThread) -> None:
    a, b = connect(served), connect(served)
    wait_clients(served, 2)
    a.sendall(b"B1.1\rS.1=10\r")
    read_until(a, b"S.1=10\r\n")
    b.sendall(b"?96.1\r")
    read_until(b, b"Px.1=", timeout=3)
    a.sendall(b"\r")
    def bank_1() -> list[str]:
        return served.call(lambda: served.chain.motors[1].banks.listing(False, 1))
    assert wait_until(lambda: bank_1() == ["S.1=10"], 3), bank_1()


def test_modbus_register_write_during_a_cml_upload_is_a_register_write() -> None:
    """5.6.7: B1.1 sent as CML at K78+102, then FC16 P0 := 777 is applied, not a bank line."""
    wire = Wire(**MANUAL)
    opened = frame("01 10 00 CA 00 03 06 42 31 2E 31 0D 00")      # "B1.1\r"
    assert wire.transact(opened) == frame("01 10 00 CA 00 03")
    write = frame("01 10 01 2C 00 02 06 00 00 03 09 0D 00")        # P0 := 777
    assert wire.transact(write) == frame("01 10 01 2C 00 02")
    assert wire.chain.get_register(1, "P", 0) == 777
    assert wire.chain.motors[1].banks.listing(False, 1) in (None, [])


def test_the_lines_of_a_client_that_sends_and_closes_all_run(served: ServiceThread) -> None:
    """``printf 'P1.1=...\\r...' | nc``: every line that arrived runs, then the upload ends."""
    a = connect(served)
    wait_clients(served, 1)
    a.sendall(b"".join(b"P%d.1=%d\r" % (i, i) for i in range(1, 201)) + b"B1.1\r")
    a.close()
    assert wait_until(lambda: served.call(lambda: served.chain.get_register(1, "P", 200))
                      == 200), "lines sent before the close were lost"
    b = connect(served)
    b.sendall(b"?96.1\r")
    assert b"Px.1=" in read_until(b, b"Px.1=", timeout=3)     # the upload ended with A
