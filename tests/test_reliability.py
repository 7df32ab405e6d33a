"""The reliability suite (docs/reliability.md), short versions.

* fuzz of every front end on one server (CML over TCP and a pty, bank uploads
  (cml-users-guide.txt 2.2.2), Modbus TCP (5.6)) with a liveness check between
  batches: a fresh client is answered at once;
* 20 clients x 200 queries on the real chain: nothing lost, duplicated or
  reordered; the p99 round trip of a one-at-a-time client while another floods;
* kill -9 of ``coolmuscle sim`` during ``$`` (2.1.2): a few rounds, the store is
  intact and holds the last acknowledged save or the one in flight.

The long versions (20 x 1,000, 100+ kill -9 rounds, a 10-hour trace) are in
bench/bench_reliability.py.  Full disk, corrupted state and signals have their
own files (tests/test_store_full_disk.py, test_store_validation.py,
test_cli_signals.py).
"""

from __future__ import annotations

import asyncio
import os
import random
import socket
import struct
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial

from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.transports.modbus_tcp import ModbusTcpTransport
from coolmuscle.frontends.transports.pty import PtyTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport
from fixtures import wait_until_async
from load_support import Flood, connect, round_trip, save_then_kill, saved_value, start_sim

SRC = str(Path(__file__).resolve().parents[1] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC, "COLUMNS": "300"}
ENV.pop("COOLMUSCLE_DEBUG", None)

CML = [b"?96.1", b"S.1=100", b"A.1=100", b"P.1=500", b"^.1", b"K23.1=16", b"K70.1=1",
       b"P1.1=12", b"?P1.1", b"]", b"*1", b"boom", b"?99.1", b"V1.1=3", b"B1.1", b"L1.1",
       b"END", b"", b"\x00\xff", b"P0.1=" + b"9" * 40, b"(" * 300, b"|1.1"]


def fuzz_bytes(rng: random.Random) -> bytes:
    """One batch: mutated CML lines, raw bytes, over-long lines, bank uploads."""
    out = bytearray()
    for _ in range(rng.randint(5, 40)):
        roll = rng.random()
        if roll < 0.5:
            line = bytearray(rng.choice(CML))
            for _ in range(rng.randint(0, 3)):
                pos = rng.randint(0, len(line))
                line[pos:pos + rng.randint(0, 2)] = bytes(rng.randrange(256)
                                                          for _ in range(rng.randint(0, 3)))
            out += line + rng.choice((b"\r", b"\n", b"\r\n"))
        elif roll < 0.7:
            out += bytes(rng.randrange(256) for _ in range(rng.randint(1, 200)))
        elif roll < 0.8:
            out += b"A" * rng.randint(500, 3000) + b"\r"
        else:
            out += b"B%d.1\r" % rng.randint(0, 40)
            for _ in range(rng.randint(0, 6)):
                out += rng.choice(CML) + b"\r"
            out += rng.choice((b"\r", b"END\r", b""))
    return bytes(out)


def mbap(tid: int, unit: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


def fuzz_modbus(rng: random.Random) -> bytes:
    out = bytearray()
    for tid in range(rng.randint(5, 60)):
        pdu = bytes(rng.randrange(256) for _ in range(rng.randint(1, 30)))
        if rng.random() < 0.5:
            pdu = bytes((rng.choice((3, 4, 16, 1, 5, 0x2B)),)) + pdu[1:]
        out += mbap(tid, rng.choice((1, 0, 255, 7)), pdu)
    return bytes(out)


@pytest.fixture
def everything(tmp_path: Path) -> Iterator[ServiceThread]:
    st_ = ServiceThread(lambda: Chain(motors=2, state_dir=tmp_path),
                        lambda: [TcpTransport(port=0), PtyTransport(),
                                 ModbusTcpTransport(port=0)]).start()
    yield st_
    st_.stop()


def probe_alive(st_: ServiceThread, timeout: float = 3.0) -> float:
    """A fresh TCP client's ``K23.1=0`` (quiet) then ``?96.2`` is answered; and Modbus."""
    start = time.monotonic()
    with connect(st_.transports[0].info()["port"], timeout) as sock:
        round_trip(sock, b"\r?96.2\r", b"Px.2=", timeout)
    with socket.create_connection(("127.0.0.1", st_.transports[2].info()["port"]),
                                  timeout=timeout) as sock:
        sock.sendall(mbap(7, 255, bytes((3, 0, 0, 0, 2))))
        reply = sock.recv(1 << 16)
        assert reply[:2] == b"\x00\x07" and len(reply) >= 9, reply
    return time.monotonic() - start


def test_fuzz_every_front_end_with_a_liveness_check_between_batches(
        everything: ServiceThread) -> None:
    rng = random.Random(16)
    tcp_port = everything.transports[0].info()["port"]
    mb_port = everything.transports[2].info()["port"]
    pty = serial.Serial(everything.transports[1].info()["path"], timeout=0)
    worst = 0.0
    try:
        for _batch in range(15):
            clients = [socket.create_connection(("127.0.0.1", tcp_port), timeout=5)
                       for _ in range(3)]
            mb = socket.create_connection(("127.0.0.1", mb_port), timeout=5)
            for sock in clients:
                sock.sendall(fuzz_bytes(rng))
            pty.write(fuzz_bytes(rng))
            mb.sendall(fuzz_modbus(rng))
            for i, sock in enumerate(clients):
                if i == 0:
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                sock.close()            # some mid-line, some mid-upload, one reset
            mb.close()
            pty.reset_input_buffer()
            worst = max(worst, probe_alive(everything))
    finally:
        pty.close()
    assert worst < 3.0
    assert everything.service is not None and everything.service.port.errors == 0


def test_twenty_clients_on_the_real_chain_lose_nothing_and_keep_order() -> None:
    """Client n sends ``V<n+1>.1=i`` then ``?96.m`` for i = 0..199 (m = n % 15 + 1).
    In the one stream every client receives: each client's V echoes are 0..199 in
    order, once each; each ``?96.m`` echo is followed at once by its ``Px.m`` reply
    (a line runs whole); the replies per motor are as many as the queries."""
    clients, queries = 20, 200
    with ServiceThread(lambda: Chain(motors=15), lambda: [TcpTransport(port=0)]) as st_:
        port = st_.transports[0].info()["port"]
        total_lines = clients * queries * 3      # V echo, ?96 echo, Px reply

        async def client(n: int, go: asyncio.Event) -> list[bytes]:
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            await go.wait()
            motor = n % 15 + 1
            writer.write(b"".join(b"V%d.1=%d\r?96.%d\r" % (n + 1, i, motor)
                                  for i in range(queries)))
            await writer.drain()
            data = bytearray()
            while data.count(b"\r\n") < total_lines:
                chunk = await asyncio.wait_for(reader.read(1 << 16), 30)
                assert chunk, "connection closed"
                data += chunk
            writer.close()
            return bytes(data).split(b"\r\n")[:-1]

        async def main() -> list[list[bytes]]:
            go = asyncio.Event()
            tasks = asyncio.gather(*(client(n, go) for n in range(clients)))
            assert await wait_until_async(lambda: st_.transports[0].clients >= clients, 10)
            go.set()
            return await asyncio.wait_for(tasks, 90)

        results = asyncio.run(main())
        assert st_.transports[0].dropped_clients == 0
        final = st_.call(lambda: st_.chain.execute("?V1.1"))
    stream = results[0]
    assert all(other == stream for other in results[1:])     # one stream for all
    assert len(stream) == total_lines
    for n in range(clients):
        values = [int(line.split(b"=")[1]) for line in stream
                  if line.startswith(b"V%d.1=" % (n + 1))]
        assert values == list(range(queries)), n
    for i, line in enumerate(stream):
        if line.startswith(b"?96."):
            assert stream[i + 1].startswith(b"Px." + line[4:] + b"="), (i, stream[i:i + 2])
    for motor in range(1, 16):
        askers = sum(1 for n in range(clients) if n % 15 + 1 == motor)
        assert sum(1 for line in stream if line.startswith(b"Px.%d=" % motor)) == \
            askers * queries
    assert "V1.1=199, V2.1=199" in final[0]


def test_p99_of_a_one_at_a_time_client_while_another_floods() -> None:
    with ServiceThread(lambda: Chain(motors=2), lambda: [TcpTransport(port=0)]) as st_:
        port = st_.transports[0].info()["port"]
        with Flood(connect(port)), connect(port) as probe:
            time.sleep(0.2)
            trips = sorted(round_trip(probe, b"?96.2\r", b"Px.2=") for _ in range(100))
    assert trips[98] < 0.5, trips[-5:]


def test_kill_9_during_dollar_leaves_the_last_save(tmp_path: Path) -> None:
    rng = random.Random(9)
    state = tmp_path / "state"
    acknowledged = 0
    for _round in range(3):
        proc, port = start_sim(state, ENV)
        acknowledged = save_then_kill(proc, port, acknowledged, rng.uniform(0.2, 0.6))
        whole, saved = saved_value(state)
        assert whole
        assert saved in (acknowledged, acknowledged + 1), (saved, acknowledged)
        acknowledged = saved


# -- EtherNet/IP (the CM1 module) -------------------------------------------------------------
def _encap(command: int, data: bytes, session: int = 0, context: bytes = b"\0" * 8) -> bytes:
    return struct.pack("<HHII8sI", command, len(data), session, 0, context, 0) + data


def _enip_alive(port: int, timeout: float = 3.0) -> None:
    """A fresh connection's RegisterSession (CIP Vol 2 2-4.4) is answered with status 0."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as sock:
        sock.sendall(_encap(0x65, struct.pack("<HH", 1, 0), context=b"alive!!!"))
        reply = b""
        while len(reply) < 28:
            chunk = sock.recv(64)
            assert chunk, reply
            reply += chunk
    command, length, session, status, context = struct.unpack("<HHII8s", reply[:20])
    assert (command, length, status, context) == (0x65, 4, 0, b"alive!!!") and session


def test_fuzz_the_ethernet_ip_front_end_with_a_liveness_check_between_batches() -> None:
    from coolmuscle.frontends.enip.server import EnipTransport

    rng = random.Random(44818)
    with ServiceThread(lambda: Chain(None, 1, firmware="cm1", state_dir=None),
                       lambda: [EnipTransport(port=0, io_port=0),
                                TcpTransport(port=0)]) as st_:
        port = st_.transports[0].info()["port"]
        cml = st_.transports[1].info()["port"]
        for _batch in range(20):
            with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
                out = bytearray()
                for _ in range(rng.randint(1, 30)):
                    roll = rng.random()
                    data = bytes(rng.randrange(256) for _ in range(rng.randint(0, 60)))
                    if roll < 0.3:
                        out += data                                     # raw garbage
                    elif roll < 0.8:                                    # a plausible header
                        out += _encap(rng.choice((0x65, 0x66, 0x6F, 0x70, 0x63, 0x04, 0x01,
                                                  rng.randrange(0x10000))),
                                      data, session=rng.choice((0, 1, rng.randrange(1 << 32))))
                    else:                                               # a lying length
                        out += struct.pack("<HH", 0x6F, rng.randrange(0x10000)) + data
                try:
                    sock.sendall(bytes(out))
                    sock.settimeout(0.05)
                    while sock.recv(1 << 16):
                        pass
                except OSError:
                    pass                        # closed by the adapter: allowed
            _enip_alive(port)
            with connect(cml, timeout=3) as sock:         # the CML line still answers
                round_trip(sock, b"\r?96.1\r", b"Px.1=", timeout=3)


# -- the web dashboard (HTTP / WebSocket) ------------------------------------------------
def _http_alive(port: int, timeout: float = 3.0) -> None:
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as sock:
        sock.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        reply = b""
        while chunk := sock.recv(1 << 16):
            reply += chunk
    assert reply.startswith(b"HTTP/1.1 ") and b" 500 " not in reply[:20], reply[:200]


def test_fuzz_the_web_front_end_with_a_liveness_check_between_batches() -> None:
    from coolmuscle.frontends.transports import create
    from coolmuscle.tools.web.server import WebTransport

    rng = random.Random(8080)
    requests = [b"GET / HTTP/1.1\r\nHost: x\r\n\r\n",
                b"POST /api HTTP/1.1\r\nContent-Length: 5\r\n\r\n",
                b"GET /ws HTTP/1.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",
                b"\x16\x03\x01\x00\xa5", b"GET /" + b"A" * 9000 + b" HTTP/1.1\r\n\r\n"]
    with ServiceThread(lambda: Chain(), lambda: [create("tcp", port=0),
                                                 WebTransport(port=0)]) as st_:
        cml, web = (t.info()["port"] for t in st_.transports)
        for _batch in range(15):
            with socket.create_connection(("127.0.0.1", web), timeout=5) as sock:
                data = bytearray(rng.choice(requests))
                for _ in range(rng.randint(0, 6)):
                    pos = rng.randint(0, len(data))
                    data[pos:pos + rng.randint(0, 4)] = bytes(rng.randrange(256)
                                                              for _ in range(rng.randint(0, 6)))
                data += bytes(rng.randrange(256) for _ in range(rng.randint(0, 300)))
                try:
                    sock.sendall(bytes(data))
                    sock.settimeout(0.05)
                    while sock.recv(1 << 16):
                        pass
                except OSError:
                    pass
            _http_alive(web)
            with connect(cml, timeout=3) as sock:         # the CML line still answers
                round_trip(sock, b"\r?96.1\r", b"Px.1=", timeout=3)
