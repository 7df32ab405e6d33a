"""TCP transport: pyserial socket://, many clients, per-client lines, slow clients, fuzz."""

from __future__ import annotations

import asyncio
import re
import socket
import struct
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest
import serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coolmuscle.errors import TransportError
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport, parse_address
from fakes import ROUNDTRIP, fake_factory, play_over_serial
from fixtures import wait_until_async

Starter = Callable[..., ServiceThread]


@pytest.fixture
def start_tcp() -> Iterator[Starter]:
    """Start a FakeChain behind a TCP transport on a free loopback port."""
    started: list[ServiceThread] = []

    def start(chain_options: dict[str, Any] | None = None, **tcp_options: Any) -> ServiceThread:
        options = {"move_time": 0.2, **(chain_options or {})}
        st_ = ServiceThread(fake_factory(**options),
                            lambda: [TcpTransport(port=0, **tcp_options)]).start()
        started.append(st_)
        return st_
    yield start
    for st_ in started:
        st_.stop()


def port_of(st_: ServiceThread) -> int:
    return st_.transports[0].info()["port"]


def connect(st_: ServiceThread) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", port_of(st_)), timeout=5)
    return sock


def read_until(sock: socket.socket, pattern: bytes, timeout: float = 5.0) -> bytes:
    """Read until ``pattern`` (a regex) matches the bytes received; fail after ``timeout``."""
    data = b""
    deadline = time.monotonic() + timeout
    while not re.search(pattern, data):
        remaining = deadline - time.monotonic()
        assert remaining > 0, f"timed out waiting for {pattern!r}; got {data!r}"
        sock.settimeout(remaining)
        chunk = sock.recv(65536)
        assert chunk, f"connection closed; got {data!r}"
        data += chunk
    return data


def test_parse_address() -> None:
    assert parse_address("5150") == ("127.0.0.1", 5150)
    assert parse_address("0.0.0.0:80") == ("0.0.0.0", 80)
    assert parse_address("[::1]:7") == ("::1", 7)
    for bad in ("x", "1:y", "70000"):
        with pytest.raises(TransportError):
            parse_address(bad)


def test_pyserial_socket_url_plays_the_transcript(start_tcp: Starter) -> None:
    st_ = start_tcp()
    port = serial.serial_for_url(f"socket://127.0.0.1:{port_of(st_)}", timeout=1)
    try:
        play_over_serial(port, ROUNDTRIP)
    finally:
        port.close()


def test_every_client_sees_replies_and_events(start_tcp: Starter) -> None:
    st_ = start_tcp()
    a, b = connect(st_), connect(st_)
    time.sleep(0.05)
    a.sendall(b"^.1\r")
    assert read_until(b, rb"Ux\.1=8\r\n") == b"^.1\r\nUx.1=8\r\n"
    assert read_until(a, rb"Ux\.1=8\r\n") == b"^.1\r\nUx.1=8\r\n"
    a.close()
    b.close()


def test_lines_of_two_clients_are_assembled_apart(start_tcp: Starter) -> None:
    """A's unfinished ``?9`` does not hold B's line: B's runs at once, A's when ended;
    each line's echo is its own whole line (two clients: echoes go out at line ends)."""
    st_ = start_tcp()
    a, b = connect(st_), connect(st_)
    time.sleep(0.05)
    a.sendall(b"?9")
    time.sleep(0.05)
    b.sendall(b"?96.1\r")
    assert read_until(b, rb"Px\.1=1\r\n") == b"?96.1\r\nPx.1=1\r\n"
    a.sendall(b"6.1\r")
    want = b"?96.1\r\nPx.1=1\r\n?96.1\r\nPx.1=2\r\n"
    assert read_until(a, rb"Px\.1=2\r\n") == want
    assert read_until(b, rb"Px\.1=2\r\n") == b"?96.1\r\nPx.1=2\r\n"
    assert st_.call(lambda: list(st_.chain.lines)) == ["?96.1", "?96.1"]


def test_a_departed_clients_half_line_is_forgotten(start_tcp: Starter) -> None:
    st_ = start_tcp()
    a, b = connect(st_), connect(st_)
    time.sleep(0.05)
    a.sendall(b"XYZ")
    time.sleep(0.05)
    a.close()
    time.sleep(0.05)
    b.sendall(b"?96.1\r")
    read_until(b, rb"Px\.1=1\r\n")
    assert st_.call(lambda: list(st_.chain.lines)) == ["?96.1"]


def test_reset_and_model_failure_do_not_affect_other_clients(start_tcp: Starter) -> None:
    st_ = start_tcp()
    a, b = connect(st_), connect(st_)
    time.sleep(0.05)
    a.sendall(b"boom\r\x00\xff garbage")
    a.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    a.close()                   # connection reset
    time.sleep(0.05)
    b.sendall(b"\r?96.1\r")
    read_until(b, rb"Px\.1=1\r\n")
    assert st_.service is not None and st_.service.port.errors == 1


def test_slow_client_is_dropped_and_the_others_keep_going(start_tcp: Starter) -> None:
    st_ = start_tcp(max_buffer=64 * 1024)
    transport = st_.transports[0]
    slow = socket.socket()
    slow.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    slow.connect(("127.0.0.1", port_of(st_)))   # never reads
    fast = connect(st_)
    time.sleep(0.05)
    sent = seen = 0
    deadline = time.monotonic() + 20
    tail = b""
    while transport.dropped_clients == 0:
        assert time.monotonic() < deadline, "slow client was never dropped"
        fast.sendall(b"?96.1\r" * 200)
        sent += 200
        while seen < sent:
            data = tail + fast.recv(65536)
            seen += data.count(b"Px.1=")
            tail = data[-8:].replace(b"Px.1=", b"")
    fast.sendall(b"?96.1\r")
    read_until(fast, rb"Px\.1=%d\r\n" % (sent + 1))
    slow.settimeout(5)
    try:            # the dropped client sees its connection end (EOF or reset)
        while slow.recv(65536):
            pass
    except ConnectionError:
        pass
    slow.close()


def test_twenty_clients_thousand_queries_each_nothing_lost(start_tcp: Starter) -> None:
    """Acceptance: 20 concurrent clients x 1,000 queries; every reply, in order."""
    clients, queries = 20, 1000
    st_ = start_tcp({"motors": clients})
    port = port_of(st_)
    total = clients * queries

    transport = st_.transports[0]

    async def client(motor: int, all_connected: asyncio.Event) -> list[bytes]:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        await all_connected.wait()   # a late joiner would miss earlier replies
        query = b"?96.%d\r" % motor
        for _ in range(queries // 100):
            writer.write(query * 100)
        await writer.drain()
        data = bytearray()
        while data.count(b"Px.") < total or not data.endswith(b"\r\n"):
            chunk = await reader.read(1 << 16)
            assert chunk, "server closed the connection"
            data += chunk
        writer.close()
        return bytes(data).split(b"\r\n")[:-1]

    async def main() -> list[list[bytes]]:
        all_connected = asyncio.Event()
        tasks = asyncio.gather(*(client(m, all_connected) for m in range(1, clients + 1)))
        assert await wait_until_async(lambda: transport.clients >= clients, 10), \
            "clients did not connect"
        all_connected.set()
        return await asyncio.wait_for(tasks, 30)

    start = time.monotonic()
    results = asyncio.run(main())
    elapsed = time.monotonic() - start
    for motor, lines in enumerate(results, 1):
        assert len(lines) == 2 * total
        echoes, replies = lines[0::2], lines[1::2]
        # every echo is followed by the reply to that very query: no interleaving
        ids = [e.removeprefix(b"?96.") for e in echoes]
        assert [r.split(b"=")[0] for r in replies] == [b"Px." + i for i in ids]
        # the replies arrive complete and in order: counters 1..total
        assert [int(r.split(b"=")[1]) for r in replies] == list(range(1, total + 1))
        assert ids.count(b"%d" % motor) == queries
    assert elapsed < 30


# -- fuzz -----------------------------------------------------------------
VALID = [b"?96.1\r", b"S.1=100\r", b"^.1\r", b"K23.1=0\r", b"boom\r", b"K70.1=1\r\n"]


def _mutate(args: tuple[bytes, int, bytes, int]) -> bytes:
    line, pos, insert, cut = args
    pos %= len(line) + 1
    return line[:pos] + insert + line[pos + cut:]


fuzz_input = st.one_of(
    st.binary(max_size=3000),
    st.integers(513, 6000).map(lambda n: b"A" * n + b"\r"),
    st.tuples(st.sampled_from(VALID), st.integers(0, 12), st.binary(max_size=4),
              st.integers(0, 3)).map(_mutate),
    st.lists(st.sampled_from(VALID), max_size=20).map(b"".join),
)


@pytest.fixture(scope="module")
def fuzz_server() -> Iterator[ServiceThread]:
    st_ = ServiceThread(fake_factory(move_time=0.01),
                        lambda: [TcpTransport(port=0)]).start()
    yield st_
    st_.stop()


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=fuzz_input, close_abruptly=st.booleans())
def test_fuzzed_input_never_stops_the_server(fuzz_server: ServiceThread, data: bytes,
                                             close_abruptly: bool) -> None:
    sock = connect(fuzz_server)
    sock.sendall(data)
    if close_abruptly:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    sock.close()
    checker = connect(fuzz_server)
    try:
        checker.sendall(b"\r?96.1\r")
        read_until(checker, rb"Px\.1=\d+\r")
    finally:
        checker.close()


def test_a_model_failure_inside_a_paced_kernel_event_does_not_stop_the_server(
        start_tcp: Starter) -> None:
    st_ = start_tcp({"pacing": True})
    sock = connect(st_)
    sock.sendall(b"boom\r?96.1\r")     # with pacing, lines reach the model in kernel events
    read_until(sock, rb"Px\.1=1\r\n")
    assert st_.service is not None and st_.service.driver.clock.errors == 1


def test_a_crlf_split_across_reads_does_not_make_a_blank_line(start_tcp: Starter) -> None:
    st_ = start_tcp()
    a, b = connect(st_), connect(st_)
    time.sleep(0.05)
    a.sendall(b"?96.1\r")
    read_until(a, rb"Px\.1=1\r\n")
    b.sendall(b"K23.1=8\r")            # echo off: b's line goes in between a's CR and LF
    time.sleep(0.05)
    a.sendall(b"\n?96.1\r")
    read_until(a, rb"Px\.1=2\r\n")
    assert st_.call(lambda: list(st_.chain.lines)) == ["?96.1", "K23.1=8", "?96.1"]
