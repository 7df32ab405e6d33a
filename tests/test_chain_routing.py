"""Routing on a 15-motor chain (cml-users-guide.txt 1.1 "up to 15 motors ... on a single
network"; 2.1 "n: Motor ID"; ch. 3 K65).

Fifteen TCP clients share the host line, each querying its own motor while every motor
runs a program bank that moves it back and forth (so ``Ux.n=8`` reports interleave with
the replies): every reply carries the ID it was asked for, with that motor's data, each
client's answers come in the order it asked, and the host line shows the events in the
order they happened.  The same with wire-time pacing, in virtual time.
"""

from __future__ import annotations

import asyncio
import re

from coolmuscle.chain.daisy import Chain
from coolmuscle.device.api import Event
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport
from coolmuscle.sim.kernel import seconds
from fixtures import ChainFactory, wait_until_async

MOTORS = 15
QUERIES = 200
REPLY = re.compile(rb"^P(\d+)\.(\d+)=(-?\d+)$")


def numbered_chain(pacing: bool = False, start: bool = True) -> Chain:
    """P1..P20 of motor n hold n*1000 + i; each motor loops a move (B1.n with X0),
    started now or later by :func:`start_banks`."""
    chain = Chain(motors=MOTORS, pacing=pacing)
    for n in range(1, MOTORS + 1):
        chain.execute(", ".join(f"P{i}.{n}={n * 1000 + i}" for i in range(1, 21)))
        chain.execute(f"P21.{n}=0, P22.{n}={n * 100}, S1.{n}={n * 10}, A1.{n}=100")
        for line in (f"B1.{n}", "X0", f"S1.{n}, A1.{n}, P22.{n}", f"P21.{n}", "X-", "END"):
            chain.execute(line)
    if start:
        start_banks(chain)
    return chain


def start_banks(chain: Chain) -> None:
    for n in range(1, MOTORS + 1):
        chain.execute(f"[1.{n}")


def query(client: int, i: int) -> bytes:
    return b"P%d.%d\r" % (i % 20 + 1, client)


def check_replies(lines: list[bytes], clients: int) -> None:
    """Right ID and data in every reply; each client's answers in its asking order."""
    answered: dict[int, list[int]] = {c: [] for c in range(1, clients + 1)}
    for line in lines:
        match = REPLY.match(line)
        if match:
            index, motor, value = (int(g) for g in match.groups())
            assert value == motor * 1000 + index, line
            answered[motor].append(index)
    for c in range(1, clients + 1):
        assert answered[c] == [i % 20 + 1 for i in range(QUERIES)]


def test_1_1_fifteen_tcp_clients_each_query_their_motor() -> None:
    events: list[Event] = []

    def factory() -> Chain:
        chain = numbered_chain(start=False)      # started once every client listens
        chain.subscribe(events.append)
        return chain

    st_ = ServiceThread(factory, lambda: [TcpTransport(port=0)], scale=5.0).start()
    try:
        port = st_.transports[0].info()["port"]
        received = asyncio.run(_clients(port, st_))
        snapshot = st_.call(lambda: list(events))
    finally:
        st_.stop()
    for lines in received:
        check_replies(lines, MOTORS)
    # every client saw the same stream (up to where it stopped reading) ...
    shortest = min(len(lines) for lines in received)
    stream = received[0][:shortest]
    assert all(lines[:shortest] == stream for lines in received[1:])
    # ... which is the motors' output in the order it happened
    printed = [e for e in snapshot if e.origin in ("host", "bank", "motor")]
    times = [e.time for e in printed]
    assert times == sorted(times)
    not_echo = [line for line in stream if REPLY.match(line) or line.startswith(b"Ux.")]
    assert not_echo == [e.text.encode() for e in printed][:len(not_echo)]
    assert sum(line.startswith(b"Ux.") for line in not_echo) > MOTORS   # moves interleaved


async def _clients(port: int, st_: ServiceThread) -> list[list[bytes]]:
    transport = st_.transports[0]

    async def client(number: int, go: asyncio.Event) -> list[bytes]:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        await go.wait()
        for start in range(0, QUERIES, 20):
            writer.write(b"".join(query(number, i) for i in range(start, start + 20)))
            await writer.drain()
            await asyncio.sleep(0.002)
        data = bytearray()
        replies = 0
        while replies < MOTORS * QUERIES:
            chunk = await reader.read(1 << 16)
            assert chunk, "server closed the connection"
            data += chunk
            replies = sum(1 for x in bytes(data).split(b"\r\n") if REPLY.match(x))
        writer.close()
        return bytes(data).split(b"\r\n")[:-1]

    go = asyncio.Event()
    tasks = asyncio.gather(*(client(c, go) for c in range(1, MOTORS + 1)))
    assert await wait_until_async(lambda: transport.clients >= MOTORS, 10), \
        "clients did not connect"
    st_.call(lambda: start_banks(st_.service.chain))
    go.set()
    return await asyncio.wait_for(tasks, 60)


def test_ch3_k65_paced_chain_interleaves_fifteen_hosts_in_time_order() -> None:
    """With wire time on the host line (K20) and the links (K65), the lines of 15 hosts
    interleaved on the line: every reply right, each motor's output in its own order,
    and the host line in the order things arrive."""
    chain = numbered_chain(pacing=True)
    chain.execute("K20.1=5, K65.1=5")         # 230.4 kbps everywhere
    produced: list[Event] = []
    chain.subscribe(produced.append)
    delivered: list[tuple[int, bytes]] = []
    buffer = bytearray()

    def on_bytes(data: bytes) -> None:
        buffer.extend(data)
        while b"\r\n" in buffer:
            line, _, rest = bytes(buffer).partition(b"\r\n")
            buffer[:] = rest
            delivered.append((chain.kernel.now, line))
    chain.host_line.add_listener(on_bytes)
    for i in range(QUERIES):
        for c in range(1, MOTORS + 1):
            chain.host_line.feed(query(c, i))
    chain.kernel.run(until=chain.kernel.now + seconds(10))
    lines = [line for _, line in delivered]
    check_replies(lines, MOTORS)
    times = [t for t, _ in delivered]
    assert times == sorted(times)
    # each delivered report or reply comes after it happened, and per motor in order
    happened: dict[bytes, list[int]] = {}
    for event in produced:
        if event.origin in ("host", "bank", "motor"):
            happened.setdefault(event.text.encode(), []).append(event.time)
    per_motor: dict[int, list[bytes]] = {}
    for t, line in delivered:
        if line in happened and happened[line]:
            assert happened[line].pop(0) <= t
            per_motor.setdefault(int(line.split(b".")[1].split(b"=")[0]), []).append(line)
    for motor, seen in per_motor.items():
        expected = [e.text.encode() for e in produced
                    if e.motor == motor and e.origin in ("host", "bank", "motor")]
        assert seen == expected[:len(seen)]
    # the reports of the farther motors took their hops: ID15's first Ux after ID1's
    first = {m: next(t for t, line in delivered if line == f"Ux.{m}=8".encode())
             for m in (1, 15)}
    assert first[15] > first[1]


def test_queries_for_absent_ids_go_unanswered(make_chain: ChainFactory) -> None:
    chain = make_chain(motors=15)
    out: list[bytes] = []
    chain.host_line.add_listener(out.append)
    chain.execute("K23.1=24")   # no echo, messages on
    chain.host_line.feed(b"?96.16\r?96.15\r")
    assert b"".join(out) == b"Px.15=0\r\n"
    assert chain.execute("?96.16") == [] and chain.execute("S.16=10") == []
