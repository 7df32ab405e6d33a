"""Connections of the TCP servers: the idle policy, dead connections, rate-limited logs.

64 connections that never send a whole request (a CML line, a Modbus ADU) must not
lock out a polite client: with every place taken, the connection idle longest among
the silent ones (or those idle beyond ``idle_timeout``) is closed to admit it
(docs/reliability.md "Connections"; the Modbus Messaging Implementation Guide's rule).
A client that pipelines requests and resets gets no more replies, so asyncio does not
log one warning per unsent reply; refusals and the other per-event lines are rate
limited.  Real chain, real sockets on loopback, real peers (pyserial, pymodbus).
"""

from __future__ import annotations

import logging
import socket
import struct
import time
from collections.abc import Iterator

import pytest
import serial
from pymodbus.client import ModbusTcpClient

from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.enip.server import EnipTransport
from coolmuscle.frontends.transports.lograte import LogLimiter
from coolmuscle.frontends.transports.modbus_tcp import ModbusTcpTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.stream_server import DEFAULT_MAX_CLIENTS
from coolmuscle.frontends.transports.tcp import TcpTransport
from fixtures import wait_until
from load_support import connect, round_trip


class Records(logging.Handler):
    """Every log record of the process while installed (asyncio's own included)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)

    def count(self, text: str, level: int = logging.DEBUG) -> int:
        return sum(1 for r in self.records if text in r.getMessage() and r.levelno >= level)


@pytest.fixture
def records() -> Iterator[Records]:
    handler = Records()
    root = logging.getLogger()
    old = root.level
    root.addHandler(handler)
    root.setLevel(logging.INFO)
    try:
        yield handler
    finally:
        root.removeHandler(handler)
        root.setLevel(old)


def silent_connections(port: int, count: int) -> list[socket.socket]:
    return [socket.create_connection(("127.0.0.1", port), timeout=5) for _ in range(count)]


def closed_by_server(sock: socket.socket, timeout: float = 5.0) -> bytes | None:
    """What the server said before it closed ``sock`` (``None``: still open)."""
    sock.settimeout(timeout)
    data = b""
    try:
        while chunk := sock.recv(4096):
            data += chunk
    except TimeoutError:
        return None
    except ConnectionResetError:
        pass
    return data


def fc03(transaction: int, address: int = 200, count: int = 2) -> bytes:
    return struct.pack(">HHHBBHH", transaction & 0xFFFF, 0, 6, 1, 3, address, count)


def reset(sock: socket.socket) -> None:
    """Close with a reset (SO_LINGER 0), as a client that crashed."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    sock.close()


# -- the idle policy ---------------------------------------------------------------------

def test_64_silent_connections_do_not_lock_out_a_pyserial_client() -> None:
    with ServiceThread(lambda: Chain(), lambda: [TcpTransport(port=0)]) as st_:
        server = st_.transports[0]
        port = server.info()["port"]
        silent = silent_connections(port, DEFAULT_MAX_CLIENTS)
        assert wait_until(lambda: server.connections == DEFAULT_MAX_CLIENTS, 10, 0.01)
        client = serial.serial_for_url(f"socket://127.0.0.1:{port}", timeout=5)
        try:
            client.write(b"?96.1\r")
            assert client.read_until(b"\r\n").startswith(b"?96.1")     # its echo
            assert client.read_until(b"\r\n").startswith(b"Px.1=")
        finally:
            client.close()
        assert server.evicted_clients == 1 and server.refused_clients == 0
        said = closed_by_server(silent[0])          # the one idle longest
        assert said is not None and said.startswith(
            b"coolmuscle: connection closed: silent for "), said
        assert said.endswith(b"while all 64 places were taken\r\n")
        for sock in silent:
            sock.close()


def test_unfinished_lines_are_no_request_a_trickler_is_closed_first() -> None:
    """A client that never ends a line (a byte now and then) holds its place only while
    there is room; a client that sent a whole line keeps its place."""
    with ServiceThread(lambda: Chain(), lambda: [TcpTransport(port=0, max_clients=3)]) as st_:
        server = st_.transports[0]
        port = server.info()["port"]
        talker = connect(port)
        assert round_trip(talker, b"?96.1\r", b"Px.1=") < 5
        tricklers = silent_connections(port, 2)
        for sock in tricklers:
            sock.sendall(b"P1.1=12")
        assert wait_until(lambda: server.connections == 3, 5, 0.01)
        newcomer = connect(port)
        assert round_trip(newcomer, b"?96.1\r", b"Px.1=") < 5
        assert closed_by_server(tricklers[0]) is not None        # the older trickler
        assert closed_by_server(tricklers[1], 0.3) is None        # the newer one stays
        assert round_trip(talker, b"?96.1\r", b"Px.1=") < 5       # the talker stays
        for sock in [talker, newcomer, *tricklers]:
            sock.close()


def test_when_every_connection_is_in_use_the_newcomer_is_refused() -> None:
    with ServiceThread(lambda: Chain(), lambda: [TcpTransport(port=0, max_clients=2)]) as st_:
        server = st_.transports[0]
        port = server.info()["port"]
        busy = [connect(port) for _ in range(2)]
        for sock in busy:
            sock.sendall(b"?96.1\r")
        assert wait_until(lambda: server.connections == 2 and server.silent_connections == 0,
                          5, 0.01)
        extra = connect(port)
        said = closed_by_server(extra)
        assert said == b"coolmuscle: too many clients (2); connection refused\r\n"
        assert server.refused_clients == 1 and server.evicted_clients == 0
        for sock in busy:
            sock.close()


def test_a_connection_idle_beyond_the_timeout_makes_room_for_a_newcomer() -> None:
    with ServiceThread(lambda: Chain(), lambda: [TcpTransport(port=0, max_clients=2,
                                                             idle_timeout=0.3)]) as st_:
        server = st_.transports[0]
        port = server.info()["port"]
        first = connect(port)
        assert round_trip(first, b"?96.1\r", b"Px.1=") < 5
        second = connect(port)
        assert round_trip(second, b"?96.1\r", b"Px.1=") < 5
        time.sleep(0.4)
        assert round_trip(second, b"?96.1\r", b"Px.1=") < 5      # second: in use again
        third = connect(port)
        assert round_trip(third, b"?96.1\r", b"Px.1=") < 5
        said = closed_by_server(first)
        assert said is not None and b"coolmuscle: connection closed: idle for 0 s" in said
        for sock in (second, third):
            sock.close()


def test_64_silent_connections_do_not_lock_out_a_pymodbus_client() -> None:
    with ServiceThread(lambda: Chain(), lambda: [ModbusTcpTransport(port=0)]) as st_:
        server = st_.transports[0]
        port = server.info()["port"]
        silent = silent_connections(port, DEFAULT_MAX_CLIENTS)
        assert wait_until(lambda: server.connections == DEFAULT_MAX_CLIENTS, 10, 0.01)
        client = ModbusTcpClient("127.0.0.1", port=port, timeout=5, retries=0)
        try:
            assert client.connect()
            assert not client.write_registers(200, [0, 777], device_id=1).isError()
            assert client.read_holding_registers(200, count=2, device_id=1).registers == [0, 777]
        finally:
            client.close()
        assert server.evicted_clients == 1 and server.refused_clients == 0
        assert closed_by_server(silent[0]) == b""
        for sock in silent:
            sock.close()


def test_a_modbus_client_that_polls_keeps_its_place() -> None:
    with ServiceThread(lambda: Chain(), lambda: [ModbusTcpTransport(port=0, max_clients=2)]
                       ) as st_:
        server = st_.transports[0]
        port = server.info()["port"]
        pollers = [connect(port) for _ in range(2)]
        for n, sock in enumerate(pollers):
            sock.sendall(fc03(n))
            assert len(sock.recv(64)) == 13
        extra = connect(port)
        assert closed_by_server(extra) == b""
        assert server.refused_clients == 1 and server.evicted_clients == 0
        for n, sock in enumerate(pollers):
            sock.sendall(fc03(10 + n))
            assert len(sock.recv(64)) == 13
            sock.close()


# -- dead connections and log lines -----------------------------------------------------

def test_a_modbus_client_that_pipelines_64k_and_resets_is_answered_no_more(
        records: Records) -> None:
    with ServiceThread(lambda: Chain(), lambda: [ModbusTcpTransport(port=0)]) as st_:
        server = st_.transports[0]
        port = server.info()["port"]
        for _ in range(3):
            sock = socket.create_connection(("127.0.0.1", port))
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            sock.sendall(b"".join(fc03(t) for t in range(65536 // 12)))
            reset(sock)
        assert wait_until(lambda: server.connections == 0, 10, 0.01)
        time.sleep(0.2)
        probe = connect(port)
        probe.sendall(fc03(1))
        assert len(probe.recv(64)) == 13
        probe.close()
    assert records.count("socket.send() raised exception") == 0
    assert server.requests < 3 * (65536 // 12)        # what was queued was not all run


def test_an_enip_client_that_pipelines_list_identity_and_resets_is_answered_no_more(
        records: Records) -> None:
    with ServiceThread(lambda: Chain(None, 1, firmware="cm1", state_dir=None),
                       lambda: [EnipTransport(port=0, io_port=0)]) as st_:
        port = st_.transports[0].info()["port"]
        list_identity = struct.pack("<HHII8sI", 0x63, 0, 0, 0, bytes(8), 0)
        sock = socket.create_connection(("127.0.0.1", port))
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.sendall(list_identity * (65536 // 24))
        reset(sock)
        assert wait_until(lambda: st_.transports[0].connections == 0, 10, 0.01)
        time.sleep(0.2)
    assert records.count("socket.send() raised exception") == 0


def test_refused_connections_are_logged_a_few_times_then_summed_up(records: Records) -> None:
    with ServiceThread(lambda: Chain(), lambda: [
            TcpTransport(port=0, max_clients=1, idle_timeout=None),
            ModbusTcpTransport(port=0, max_clients=1, idle_timeout=None)]) as st_:
        tcp, modbus = st_.transports
        kept = [connect(tcp.info()["port"]), connect(modbus.info()["port"])]
        assert wait_until(lambda: tcp.connections == 1 and modbus.connections == 1, 5, 0.01)
        for _ in range(300):
            for server in (tcp, modbus):
                extra = connect(server.info()["port"])
                extra.close()
        assert wait_until(lambda: tcp.refused_clients == modbus.refused_clients == 300,
                          10, 0.01)
        for sock in kept:
            sock.close()
    refused = [r for r in records.records if "refused" in r.getMessage()
               and r.levelno >= logging.WARNING]
    assert len(refused) <= 2 * (5 + 1), [r.getMessage() for r in refused]
    summaries = [r.getMessage() for r in refused if "more refused connections" in r.getMessage()]
    assert sum(int(text.split()[0]) for text in summaries) == 2 * (300 - 5)


def test_the_log_limiter_says_the_first_lines_then_one_summary_per_window(
        records: Records) -> None:
    now = [0.0]
    logger = logging.getLogger("coolmuscle.test.lograte")
    limiter = LogLimiter(logger, logging.WARNING, "refused connections", burst=3,
                         interval=10.0, clock=lambda: now[0])
    said = [limiter("refused %d", n) for n in range(100)]
    assert said == [True] * 3 + [False] * 97
    now[0] = 10.0
    assert limiter("refused %d", 100)             # a new window: the summary first
    lines = [r.getMessage() for r in records.records if r.name == logger.name]
    assert lines == ["refused 0", "refused 1", "refused 2",
                     "97 more refused connections in 10 s (at most 3 such lines every 10 s)",
                     "refused 100"]
    limiter.flush()
    assert len(records.records) == 5              # nothing left out since


def test_a_scheduled_summary_comes_when_the_window_ends(records: Records) -> None:
    now = [0.0]
    calls: list[tuple[float, object]] = []
    logger = logging.getLogger("coolmuscle.test.lograte")
    limiter = LogLimiter(logger, logging.WARNING, "resets", burst=1, interval=5.0,
                         clock=lambda: now[0], schedule=lambda d, f: calls.append((d, f)))
    for _ in range(4):
        limiter("reset")
    assert len(calls) == 1 and calls[0][0] == 5.0
    now[0] = 5.0
    calls[0][1]()                                       # type: ignore[operator]
    assert [r.getMessage() for r in records.records][-1].startswith("3 more resets in 5 s")
