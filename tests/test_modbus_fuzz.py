"""Fuzz: malformed Modbus frames get exactly the right silence or exception; the slave serves on.

Each malformed request is built *by category*, so its expected answer is known from
the manual (5.6.3, 5.6.7 table, 5.6.8) and docs/fidelity.md "Modbus" without
asking the implementation: exception 01 for a function the host side does not have,
02 for an address or count outside the 5.6.7 table, silence for a bad CRC, a frame
too short or too long for its function, a function code with the error bit, another
address.  10,000 frames over RTU (virtual time, through the host line) and 10,000
over Modbus TCP (a real socket), plus a smaller run over a real pseudo-terminal.
"""

from __future__ import annotations

import random
import socket
import time
from collections.abc import Callable, Iterator

import pytest
import serial

from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.transports.modbus_tcp import ModbusTcpTransport
from coolmuscle.frontends.transports.serial_line import ModbusRtuTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.sim.kernel import ms
from modbus_support import Wire, crc

UNIT = 1
P0_VALUE = 4242
PROBE = bytes.fromhex("03 00 C8 00 02")                    # FC03 P0 (K78=0)
PROBE_REPLY = bytes.fromhex("03 04 00 00") + P0_VALUE.to_bytes(2, "big")

#: Word offsets of the 5.6.7 FC03 table (K78-relative), written out from the manual.
HOLDING = (set(range(0, 42)) | set(range(52, 60)) | set(range(200, 672))
           | set(range(686, 688)) | set(range(696, 712)) | set(range(752, 892)))
#: Value starts FC16 may write (V, P, S, A, M, H0, T1-T8, K20-K89).
WRITABLE = (set(range(10, 42, 2)) | set(range(200, 672, 2)) | set(range(696, 712, 2))
            | set(range(752, 892, 2)))
INPUT = set(range(0, 15)) | set(range(16, 31)) | set(range(32, 47))

Case = tuple[str, bytes, bytes | None]     # category, PDU, expected response PDU


def _word(value: int) -> bytes:
    return value.to_bytes(2, "big")


def _exception(function: int, code: int) -> bytes:
    return bytes((function | 0x80, code))


def _gap_range(rng: random.Random, table: set[int], top: int = 2000) -> tuple[int, int]:
    """A start and count (1..125) that cover at least one word outside ``table``."""
    while True:
        count = rng.randint(1, 125)
        start = rng.randint(0, top)
        if any(w not in table for w in range(start, start + count)):
            return start, count


def malformed_pdus(rng: random.Random) -> Iterator[Case]:
    """Endless malformed requests, each with its expected answer (None: silence)."""
    generators: list[Callable[[], Case]] = []

    def unknown_function() -> Case:
        function = rng.choice([f for f in range(0x80) if f not in (3, 4, 16)])
        pdu = bytes((function,)) + rng.randbytes(rng.randint(0, 20))
        return "unknown function", pdu, _exception(function, 1)

    def error_bit_function() -> Case:
        return "function with error bit", bytes((rng.randint(0x80, 0xFF),)) + \
            rng.randbytes(rng.randint(0, 8)), None

    def read_gap() -> Case:
        function = rng.choice((3, 4))
        start, count = _gap_range(rng, HOLDING if function == 3 else INPUT)
        return "illegal address", bytes((function,)) + _word(start) + _word(count), \
            _exception(function, 2)

    def huge_count() -> Case:
        function = rng.choice((3, 4))
        count = rng.choice((0, rng.randint(126, 0xFFFF)))
        return "huge count", bytes((function,)) + _word(rng.choice((200, 0, 32))) + \
            _word(count), _exception(function, 2)

    def read_wrong_length() -> Case:
        full = bytes((rng.choice((3, 4)),)) + _word(200) + _word(2)
        if rng.random() < 0.5:
            pdu = full[:rng.randint(1, 4)]
        else:
            pdu = full + rng.randbytes(rng.randint(1, 40))
        return "read too short or long", pdu, None

    def write_not_writable() -> Case:
        kind = rng.randrange(4)
        if kind == 0:     # a start that is not a writable value (nor a CML input)
            start = rng.choice([a for a in range(0, 1000) if a not in WRITABLE
                                and a not in (100, 102)])
            count = 2
        elif kind == 1:   # odd counts
            start, count = rng.choice(sorted(WRITABLE)), rng.choice((1, 3, 5, 121))
        elif kind == 2:   # more than 123 registers
            start, count = 200, rng.randint(124, 0xFFFE) & ~1
        else:             # runs past the last writable value
            start, count = 890, 4
        data = rng.randbytes(rng.randint(0, 12))
        return "write outside the table", bytes((16,)) + _word(start) + _word(count) + \
            bytes((len(data),)) + data, _exception(16, 2)

    def write_bad_data() -> Case:
        start = rng.choice(range(200, 600, 2))      # P data: a bad frame must not write
        count = 2 * rng.randint(1, 4)
        size = 2 * count
        if rng.random() < 0.5:
            data = rng.randbytes(rng.randint(0, size - 1))
        else:
            data = rng.randbytes(size) + rng.choice((b"A", b"\r\x00\x00", b"\x00",
                                                     rng.randbytes(rng.randint(3, 30))))
        pdu = bytes((16,)) + _word(start) + _word(count) + bytes((len(data) & 0xFF,)) + data
        if rng.random() < 0.2:
            pdu = pdu[:rng.randint(1, 5)]           # not even a byte count
        return "write data does not fit", pdu, None

    generators += [unknown_function, error_bit_function, read_gap, huge_count,
                   read_wrong_length, write_not_writable, write_bad_data]
    while True:
        yield rng.choice(generators)()


def rtu(unit: int, pdu: bytes) -> bytes:
    head = bytes((unit,)) + pdu
    return head + crc(head)


def malformed_rtu(rng: random.Random) -> Iterator[tuple[str, bytes, bytes | None]]:
    """RTU frames: the PDU cases plus framing faults; expected reply is a whole frame."""
    pdus = malformed_pdus(rng)
    while True:
        roll = rng.random()
        if roll < 0.12:
            good = rtu(UNIT, PROBE if rng.random() < 0.5 else next(pdus)[1])
            i = rng.randrange(len(good))
            yield "bad CRC", good[:i] + bytes((good[i] ^ (1 << rng.randrange(8)),)) + \
                good[i + 1:], None
        elif roll < 0.17:
            yield "short frame", rng.randbytes(rng.randint(1, 3)), None
        elif roll < 0.20:
            yield "longer than 256", rtu(UNIT, rng.randbytes(rng.randint(255, 400))), None
        elif roll < 0.25:
            yield "other address", rtu(rng.randint(2, 255), PROBE), None
        elif roll < 0.28:
            yield "broadcast", rtu(0, next(pdus)[1]), None
        else:
            category, pdu, reply = next(pdus)
            yield category, rtu(UNIT, pdu), None if reply is None else rtu(UNIT, reply)


def test_fuzz_10000_malformed_frames_over_rtu_in_virtual_time() -> None:
    wire = Wire(K81_1=1)
    wire.chain.set_register(1, "P", 0, P0_VALUE)
    rng = random.Random(56)
    frames = malformed_rtu(rng)
    seen: dict[str, int] = {}
    for i in range(10_000):
        category, data, expected = next(frames)
        seen[category] = seen.get(category, 0) + 1
        assert wire.transact(data, wait_ns=ms(2)) == (expected or b""), (i, category, data.hex())
        if i % 50 == 49:
            assert wire.transact(rtu(UNIT, PROBE), wait_ns=ms(2)) == rtu(UNIT, PROBE_REPLY)
    assert len(seen) >= 12 and min(seen.values()) > 100, seen
    assert wire.chain.get_register(1, "P", 0) == P0_VALUE       # no malformed write landed
    assert wire.chain.modbus_line.active()


# -- Modbus TCP -----------------------------------------------------------------------
def mbap(tid: int, unit: int, pdu: bytes, protocol: int = 0) -> bytes:
    return _word(tid) + _word(protocol) + _word(len(pdu) + 1) + bytes((unit,)) + pdu


def recv_exactly(sock: socket.socket, size: int) -> bytes:
    data = bytearray()
    while len(data) < size:
        chunk = sock.recv(size - len(data))
        assert chunk, f"connection closed after {len(data)} of {size} bytes"
        data += chunk
    return bytes(data)


@pytest.fixture
def tcp_sim() -> Iterator[tuple[ServiceThread, int]]:
    def chain() -> Chain:
        c = Chain(motors=1)
        c.set_register(1, "P", 0, P0_VALUE)
        return c
    st = ServiceThread(chain, lambda: [ModbusTcpTransport(port=0)]).start()
    try:
        yield st, st.transports[0].info()["port"]
    finally:
        st.stop()


def test_fuzz_10000_malformed_frames_over_tcp(tcp_sim: tuple[ServiceThread, int]) -> None:
    """Pipelined: every malformed ADU is followed by a probe; the byte stream back must be
    exactly the expected exceptions and probe answers, in order."""
    st, port = tcp_sim
    rng = random.Random(1502)
    pdus = malformed_pdus(rng)
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        tid = 0
        for _batch in range(100):
            sent, expected = bytearray(), bytearray()
            for _ in range(100):
                roll = rng.random()
                unit, protocol, (_category, pdu, reply) = UNIT, 0, next(pdus)
                if roll < 0.05:
                    unit, reply = rng.choice((2, 3, 100, 254)), None
                elif roll < 0.08:
                    protocol, reply = rng.randint(1, 0xFFFF), None
                elif roll < 0.11:
                    unit, reply = 0, None                       # broadcast
                sent += mbap(tid, unit, pdu, protocol)
                if reply is not None:
                    expected += mbap(tid, unit, reply)
                tid = (tid + 1) & 0xFFFF
                sent += mbap(tid, UNIT, PROBE)
                expected += mbap(tid, UNIT, PROBE_REPLY)
                tid = (tid + 1) & 0xFFFF
            sock.sendall(sent)
            assert recv_exactly(sock, len(expected)) == bytes(expected)
    assert st.call(st.chain.get_register, 1, "P", 0) == P0_VALUE


@pytest.mark.parametrize("length", [0, 1, 255, 0xFFFF])
def test_tcp_a_length_without_framing_closes_only_that_connection(
        tcp_sim: tuple[ServiceThread, int], length: int) -> None:
    st, port = tcp_sim
    with socket.create_connection(("127.0.0.1", port), timeout=5) as other, \
            socket.create_connection(("127.0.0.1", port), timeout=5) as bad:
        bad.sendall(_word(7) + _word(0) + _word(length) + b"\x01" + PROBE)
        assert bad.recv(100) == b""                      # closed
        other.sendall(mbap(9, UNIT, PROBE))
        assert recv_exactly(other, 13) == mbap(9, UNIT, PROBE_REPLY)


# -- RTU over a real pseudo-terminal -------------------------------------------------------
def test_fuzz_malformed_frames_over_a_real_pty() -> None:
    """The same frames through the pty front end in real time; probes prove it serves on."""
    def chain() -> Chain:
        c = Chain(motors=1)
        c.set_register(1, "P", 0, P0_VALUE)
        c.set_param(1, 20, 5)                            # 230.4 kbps: 0.28 ms interval
        return c
    st = ServiceThread(chain, lambda: [ModbusRtuTransport("pty")]).start()
    try:
        path = st.transports[0].info()["path"]
        rng = random.Random(232)
        frames = malformed_rtu(rng)
        probe, probe_reply = rtu(UNIT, PROBE), rtu(UNIT, PROBE_REPLY)
        with serial.Serial(path, 230400, timeout=2) as port:
            for i in range(1000):
                category, data, expected = next(frames)
                port.write(data)
                if expected is not None:
                    assert port.read(len(expected)) == expected, (i, category, data.hex())
                    continue
                time.sleep(0.004)                        # silence ends the message
                for _attempt in range(3):                # a late read may merge it with us
                    port.write(probe)
                    port.timeout = 0.3
                    got = port.read(len(probe_reply))
                    port.timeout = 2
                    if got:
                        break
                    time.sleep(0.01)
                assert got == probe_reply, (i, category, data.hex(), got.hex())
            assert port.in_waiting == 0
    finally:
        st.stop()


def test_fuzz_2000_random_cml_commands_are_acknowledged_and_the_slave_serves_on() -> None:
    """Any bytes at the CML inputs (K78+100 / +102) are a command the motor parses as it
    parses the host line; the FC16 answer is always the echo of address and count."""
    wire = Wire(K81_1=1, K23_1=17)
    wire.chain.set_register(1, "P", 0, P0_VALUE)
    rng = random.Random(102)
    alphabet = b"PSAMTVKO?^()|*]}$#=+-,.:;!&<>\"0123456789 \r\x00\n\xff"
    for i in range(2000):
        size = rng.randint(0, 40)
        data = bytes(rng.choice(alphabet) for _ in range(size)) if i % 2 else rng.randbytes(size)
        start = rng.choice((100, 102))
        count = rng.randint(0, 0xFFFF)
        head = bytes((16,)) + _word(start) + _word(count)
        reply = wire.transact(rtu(UNIT, head + bytes((len(data) & 0xFF,)) + data),
                              wait_ns=ms(2))
        assert reply == rtu(UNIT, head), (i, data)
        if i % 50 == 49:   # the command may have changed P0: check the form of the answer
            probe = wire.transact(rtu(UNIT, PROBE), wait_ns=ms(2))
            assert probe[:3] == b"\x01\x03\x04" and probe[-2:] == crc(probe[:-2]), probe
    assert wire.chain.modbus_line.failures == 0
