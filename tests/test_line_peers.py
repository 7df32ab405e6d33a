"""The real motor model behind every text front door, talked to by independent peers.

The cml-users-guide.txt 2.1 golden transcript is played over pyserial on the
pseudo-terminal, on ``socket://`` (TCP), on ``coolmuscle://`` (in-process) and through
socat bridging a pty of its own to the TCP port.  Then 20 TCP clients x 1,000 queries,
and fuzzing of the line protocol with the real model.
"""

from __future__ import annotations

import asyncio
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import coolmuscle
from coolmuscle.chain.daisy import Chain
from coolmuscle.cml.parser import parse
from coolmuscle.errors import CmlSyntaxError
from coolmuscle.frontends.transports.pty import PtyTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport
from fakes import play_over_serial
from fixtures import wait_until, wait_until_async

TRANSCRIPT = (Path(__file__).parent / "transcripts" / "2.1-operation-example.cml").read_text()
SCALE = 10.0   # virtual time runs 10x the wall clock: the 1.1 s move takes 0.11 s


@pytest.fixture
def served() -> Iterator[ServiceThread]:
    """A real one-motor chain behind a TCP port and a pseudo-terminal."""
    st_ = ServiceThread(lambda: Chain(), lambda: [TcpTransport(port=0), PtyTransport()],
                        scale=SCALE).start()
    yield st_
    st_.stop()


def tcp_port(st_: ServiceThread) -> int:
    return st_.transports[0].info()["port"]


def test_2_1_transcript_over_pyserial_on_the_pty(served: ServiceThread) -> None:
    path = served.transports[1].info()["path"]
    with serial.Serial(path, baudrate=38400, timeout=1) as port:
        play_over_serial(port, TRANSCRIPT)


def test_2_1_transcript_over_pyserial_socket_url(served: ServiceThread) -> None:
    with serial.serial_for_url(f"socket://127.0.0.1:{tcp_port(served)}", timeout=1) as port:
        play_over_serial(port, TRANSCRIPT)


def test_2_1_transcript_over_the_coolmuscle_url() -> None:
    coolmuscle.register_url_handler()
    with serial.serial_for_url(f"coolmuscle://?scale={SCALE:g}", timeout=1) as port:
        play_over_serial(port, TRANSCRIPT)


@pytest.mark.skipif(shutil.which("socat") is None, reason="socat is installed by scripts/test")
def test_2_1_transcript_through_a_socat_pty_bridged_to_tcp(served: ServiceThread,
                                                          tmp_path: Path) -> None:
    link = tmp_path / "ttyCM"
    bridge = subprocess.Popen(["socat", f"PTY,link={link},raw,echo=0",
                               f"TCP:127.0.0.1:{tcp_port(served)}"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        assert wait_until(link.exists), "socat did not create its pty"
        with serial.Serial(str(link), baudrate=38400, timeout=1) as port:
            play_over_serial(port, TRANSCRIPT)
    finally:
        bridge.terminate()
        bridge.wait(5)


def test_twenty_clients_thousand_queries_against_the_real_motor() -> None:
    """20 concurrent clients x 1,000 register queries: every reply, in order, none lost."""
    clients, queries = 20, 1000
    st_ = ServiceThread(_numbered_chain, lambda: [TcpTransport(port=0)]).start()
    try:
        results = asyncio.run(_run_clients(tcp_port(st_), st_, clients, queries))
    finally:
        st_.stop()
    total = clients * queries
    for lines in results:
        assert len(lines) == 2 * total
        echoes, replies = lines[0::2], lines[1::2]
        # each echo is followed by the reply to that very query
        assert [r.split(b"=")[0] for r in replies] == echoes
        assert all(r == e + b"=" + e[1:].split(b".")[0] for e, r in zip(echoes, replies))
    for client in range(clients):   # each client's own queries come back in sending order
        mine = [e for e in results[0][0::2] if (int(e[1:].split(b".")[0]) - 1) // 10 == client]
        assert mine == [_query(client, i).rstrip(b"\r") for i in range(queries)]


def _numbered_chain() -> Chain:
    chain = Chain()
    for index in range(1, 201):
        chain.execute(f"P{index}.1={index}")
    return chain


def _query(client: int, i: int) -> bytes:
    return b"P%d.1\r" % (client * 10 + i % 10 + 1)


async def _run_clients(port: int, st_: ServiceThread, clients: int,
                       queries: int) -> list[list[bytes]]:
    total = clients * queries
    transport = st_.transports[0]

    async def client(number: int, go: asyncio.Event) -> list[bytes]:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        await go.wait()
        for start in range(0, queries, 100):
            writer.write(b"".join(_query(number, i) for i in range(start, start + 100)))
        await writer.drain()
        data = bytearray()
        while data.count(b"\r\n") < 2 * total:
            chunk = await reader.read(1 << 16)
            assert chunk, "server closed the connection"
            data += chunk
        writer.close()
        return bytes(data).split(b"\r\n")[:-1]

    go = asyncio.Event()
    tasks = asyncio.gather(*(client(c, go) for c in range(clients)))
    assert await wait_until_async(lambda: transport.clients >= clients, 10), \
        "clients did not connect"
    go.set()
    return await asyncio.wait_for(tasks, 60)


# -- fuzzing the line protocol with the real model ------------------------------------
VALID = ["?96.1", "S.1=100", "A.1=100", "P.1=500", "^.1", "K23.1=17", "K70.1=0",
         "P1.1=P2.1+V3.1", "V1.1=\"Px\"", "I1.1, O1.1, F1.1", "?90.1", "$.1", "*", "*1",
         "(.1", ").1", "|2.1", "].1", "?999.1", "K37.1=9"]
lines = st.one_of(
    st.text(max_size=80),
    st.binary(max_size=200).map(lambda b: b.decode("latin-1")),
    st.tuples(st.sampled_from(VALID), st.integers(0, 20), st.text(max_size=3),
              st.integers(0, 3)).map(lambda t: t[0][:t[1] % (len(t[0]) + 1)] + t[2]
                                     + t[0][t[1] % (len(t[0]) + 1) + t[3]:]),
    st.integers(400, 2000).map(lambda n: "9" * n),
)


@settings(max_examples=300, deadline=None)
@given(st.lists(lines, min_size=1, max_size=8))
def test_fuzzed_lines_get_the_documented_answer_and_the_motor_keeps_serving(
        batch: list[str]) -> None:
    """Each line is echoed; a line that does not parse gives error01 (K23 has 16)."""
    chain = Chain()
    chain.execute("K23.1=17")
    out = bytearray()
    chain.host_line.add_listener(out.extend)
    for text in batch:
        wire = text.replace("\r", "").replace("\n", "").encode("latin-1", "replace")
        echo = not chain.motors[1].k(23) & 8          # settings in force when CR arrives
        delimiter = b"\r\n" if chain.motors[1].k(70) == 1 else b"\r"
        out.clear()
        chain.host_line.feed(wire + b"\r")
        chain.kernel.advance(1_000_000)
        if not echo or len(wire) > 512:
            continue
        assert out.startswith(wire + delimiter)
        try:
            parse(wire.decode("latin-1"))   # what the motor received
        except CmlSyntaxError:
            if chain.motors[1].k(23) & 16:
                assert b"error01.1: syntax error!!" in out
    chain.execute("*1")
    assert chain.execute("?96.1")[0].startswith("Px.1=")


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=2000))
def test_fuzzed_bytes_over_tcp_never_stop_the_real_motor(served: ServiceThread,
                                                          data: bytes) -> None:
    with socket.create_connection(("127.0.0.1", tcp_port(served)), timeout=5) as sock:
        sock.sendall(data)
    with socket.create_connection(("127.0.0.1", tcp_port(served)), timeout=5) as sock:
        sock.sendall(b"\rK23.1=1\r*1\r?96.1\r")
        received = b""
        deadline = time.monotonic() + 5
        while b"Px.1=" not in received:
            assert time.monotonic() < deadline, f"no answer; got {received!r}"
            received += sock.recv(65536)
