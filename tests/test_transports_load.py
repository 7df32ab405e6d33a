"""Served transports under load: bounded work per wake-up and bounded memory per client.

A Modbus TCP client pipelining 64 KB of FC03 requests (cml-users-guide.txt 5.6.7)
or a CML client flooding ``$`` must not stop the motor's time or another client's
round trip; many connections are refused beyond a limit with a clear line, and
each client's queued output is bounded.  Real chain, real sockets on loopback.
"""

from __future__ import annotations

import socket
import struct
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

import coolmuscle.frontends.transports.tcp as tcp_module
from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.transports.base import DEFAULT_MAX_BUFFER
from coolmuscle.frontends.transports.modbus_tcp import ModbusTcpTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport
from fixtures import wait_until
from load_support import Flood, connect, round_trip


@pytest.fixture
def served(tmp_path: Path) -> Iterator[ServiceThread]:
    st_ = ServiceThread(lambda: Chain(motors=2, state_dir=tmp_path),
                        lambda: [TcpTransport(port=0), ModbusTcpTransport(port=0)]).start()
    yield st_
    st_.stop()


def test_64k_of_pipelined_modbus_requests_do_not_freeze_another_client(
        served: ServiceThread) -> None:
    cml = connect(served.transports[0].info()["port"])
    modbus = connect(served.transports[1].info()["port"])
    fc03 = b"".join(struct.pack(">HHHB", t & 0xFFFF, 0, 6, 1) + bytes((3, 0, 0, 0, 10))
                    for t in range(65536 // 12))
    with Flood(modbus, line=None, poll=2.0):
        trips = []
        for _ in range(5):
            modbus.sendall(fc03)
            trips.append(round_trip(cml, b"?96.1\r", b"Px.1="))
    assert max(trips) < 0.5, trips


def test_a_flood_of_saves_does_not_hold_another_clients_query(served: ServiceThread) -> None:
    port = served.transports[0].info()["port"]
    flood, probe = connect(port), connect(port)
    flood.sendall(b"$\r" * 400)
    with Flood(flood, line=None), probe:
        time.sleep(0.05)
        assert round_trip(probe, b"?96.2\r", b"Px.2=") < 1.0


def test_connections_beyond_the_limit_are_refused_with_one_line() -> None:
    with ServiceThread(lambda: Chain(), lambda: [TcpTransport(port=0, max_clients=3)]) as st_:
        port = st_.transports[0].info()["port"]
        kept = [connect(port) for _ in range(3)]
        for sock in kept:              # in use: the idle policy closes none of them
            sock.sendall(b"?96.1\r")
        assert wait_until(lambda: st_.transports[0].connections == 3
                          and st_.transports[0].silent_connections == 0, 5, 0.01)
        extra = connect(port)
        data = b""
        while chunk := extra.recv(4096):
            data += chunk
        assert data == b"coolmuscle: too many clients (3); connection refused\r\n"
        assert round_trip(kept[0], b"?96.1\r", b"Px.1=") < 2
        for sock in kept + [extra]:
            sock.close()


def test_modbus_connections_beyond_the_limit_are_closed() -> None:
    with ServiceThread(lambda: Chain(),
                       lambda: [ModbusTcpTransport(port=0, max_clients=2)]) as st_:
        port = st_.transports[0].info()["port"]
        kept = [connect(port) for _ in range(2)]
        for n, sock in enumerate(kept):     # in use: the idle policy closes none of them
            sock.sendall(struct.pack(">HHHBBHH", n, 0, 6, 1, 3, 200, 2))
            assert len(sock.recv(64)) == 13
        extra = connect(port)
        extra.settimeout(5)
        assert extra.recv(4096) == b""
        assert st_.transports[0].refused_clients == 1
        for sock in kept + [extra]:
            sock.close()


def test_non_reading_clients_are_bounded_and_dropped_alone() -> None:
    """Every non-reader's queue stays under ``max_buffer``; the reader is never dropped."""
    bound = 64 * 1024
    with ServiceThread(lambda: Chain(),
                       lambda: [TcpTransport(port=0, max_buffer=bound)]) as st_:
        port = st_.transports[0].info()["port"]
        transport = st_.transports[0]
        idle = []
        for _ in range(10):
            sock = socket.socket()
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            sock.connect(("127.0.0.1", port))
            idle.append(sock)
        reader = connect(port)
        assert wait_until(lambda: transport.clients >= 11, 5, 0.01)
        peak = 0
        deadline = time.monotonic() + 30
        while transport.dropped_clients < 10:
            assert time.monotonic() < deadline, transport.dropped_clients
            round_trip(reader, b"?P1.1\r" * 20, b"P197.1=", count=20)
            peak = max(peak, max((c.unread() for c in list(transport._clients)), default=0))
        assert peak <= bound
        # the dropped ones are forgotten
        assert wait_until(lambda: transport.clients == 1, 5, 0.01), transport.clients
        assert round_trip(reader, b"?96.1\r", b"Px.1=") < 2
        for sock in idle + [reader]:
            sock.close()
    assert DEFAULT_MAX_BUFFER * tcp_module.DEFAULT_MAX_CLIENTS <= 32 << 20


def test_with_wire_pacing_a_flood_does_not_queue_ahead_of_another_client() -> None:
    """--pace (K20 wire time): a flood is fed to the wire as it frees, so another
    client's line waits one turn of the wire, not the flood's whole wire time."""
    with ServiceThread(lambda: Chain(motors=2, pacing=True),
                       lambda: [TcpTransport(port=0)]) as st_:
        port = st_.transports[0].info()["port"]
        flood, probe = connect(port), connect(port)
        flood.sendall(b"?99.1\r" * 2000)         # 12 KB: 3 s of wire time at 38.4 kbps
        with Flood(flood, line=None), probe:
            time.sleep(0.2)
            assert round_trip(probe, b"?96.2\r", b"Px.2=") < 1.0
