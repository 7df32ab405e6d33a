"""Independent peers: pymodbus and Debian's mbpoll as masters, a pymodbus server as COM1 slave.

The simulator runs as ``coolmuscle sim`` does (a real-time service thread); the
masters reach it over a socat pseudo-terminal pair (Modbus RTU on COM0, 5.6.1) and
over Modbus TCP.  Each master writes and reads the map of 5.6.7, gets exception 02
for a gap, and sends a CML command at K78+102 that moves the motor.
"""

from __future__ import annotations

import re
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Protocol

import pytest
import serial
from pymodbus.client import ModbusSerialClient, ModbusTcpClient

from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.transports.modbus_tcp import ModbusTcpTransport
from coolmuscle.frontends.transports.serial_line import Com1Transport, ModbusRtuTransport
from coolmuscle.frontends.transports.service import ServiceThread
from modbus_support import needs_mbpoll, needs_socat, socat_pty_pair, wait_for

pytestmark = pytest.mark.peer

MOVE = b"S.1=100, A.1=100, P.1=2000, ^.1\r"


def ascii_words(text: bytes) -> list[int]:
    """A CML command as registers: two characters a word, NUL padding (5.6.7)."""
    if len(text) % 2:
        text += b"\x00"
    return [int.from_bytes(text[i:i + 2], "big") for i in range(0, len(text), 2)]


class Master(Protocol):
    def read(self, address: int, count: int, function: int = 3) -> list[int] | int:
        """Registers, or the exception code."""

    def write(self, address: int, words: list[int]) -> int | None:
        """``None``, or the exception code."""


class Pymodbus:
    def __init__(self, client: Any) -> None:
        self.client = client
        assert client.connect()

    def read(self, address: int, count: int, function: int = 3) -> list[int] | int:
        call = (self.client.read_holding_registers if function == 3
                else self.client.read_input_registers)
        reply = call(address, count=count, device_id=1)
        return int(reply.exception_code) if reply.isError() else list(reply.registers)

    def write(self, address: int, words: list[int]) -> int | None:
        reply = self.client.write_registers(address, words, device_id=1)
        return int(reply.exception_code) if reply.isError() else None


class Mbpoll:
    EXCEPTIONS = {"Illegal function": 1, "Illegal data address": 2}

    def __init__(self, *where: str) -> None:
        self.where = list(where)

    def _run(self, args: list[str]) -> subprocess.CompletedProcess[str]:
        return subprocess.run(["mbpoll", "-a", "1", "-o", "2", *args, *self.where],
                              capture_output=True, text=True, timeout=10)

    def _exception(self, out: subprocess.CompletedProcess[str]) -> int:
        for text, code in self.EXCEPTIONS.items():
            if text in out.stderr + out.stdout:
                return code
        raise AssertionError(f"mbpoll failed: {out.stderr or out.stdout}")

    def read(self, address: int, count: int, function: int = 3) -> list[int] | int:
        kind = "4:hex" if function == 3 else "3:hex"
        out = self._run(["-r", str(address + 1), "-c", str(count), "-t", kind, "-1"])
        if out.returncode:
            return self._exception(out)
        return [int(v, 16) for v in re.findall(r"^\[\d+\]:\s+0x([0-9A-F]{4})", out.stdout,
                                               re.MULTILINE)]

    def write(self, address: int, words: list[int]) -> int | None:
        self.where, device = self.where[:-1], self.where[-1:]
        try:
            out = self._run(["-r", str(address + 1), "-t", "4:hex", *device,
                             *(f"0x{w:04X}" for w in words)])
        finally:
            self.where += device
        if out.returncode:
            return self._exception(out)
        assert f"Written {len(words)} references" in out.stdout
        return None


def exercise(master: Master, st: ServiceThread) -> None:
    """Write and read the map, a gap, FC04, and a CML command that moves the motor."""
    assert master.write(200, [0, 12345]) is None                     # P0 (K78=0)
    assert master.write(202, [0xFFFF, 0xFFFB]) is None               # P1 = -5
    assert master.read(200, 4) == [0, 12345, 0xFFFF, 0xFFFB]
    assert st.call(st.chain.get_register, 1, "P", 1) == -5
    assert master.read(752 + 2 * 22, 2) == [0, 10]                   # K42 factory value
    assert master.read(42, 2) == 2                                   # no value there
    assert master.write(0, [0, 1]) == 2                              # Pe is read only
    assert master.read(32, 1, function=4) == [8]                     # Ux of ID1
    assert master.write(102, ascii_words(MOVE)) is None
    assert wait_for(lambda: master.read(2, 2) == [0, 2000] and master.read(8, 2) == [0, 8])
    assert st.call(lambda: st.chain.snapshot(1).position) == 2000


@pytest.fixture
def sim_rtu(tmp_path: Path) -> Iterator[tuple[ServiceThread, str]]:
    with socat_pty_pair(tmp_path) as (ours, theirs):
        st = ServiceThread(lambda: Chain(motors=1),
                           lambda: [ModbusRtuTransport(where=ours)]).start()
        try:
            yield st, theirs
        finally:
            st.stop()


@pytest.fixture
def sim_tcp() -> Iterator[tuple[ServiceThread, int]]:
    st = ServiceThread(lambda: Chain(motors=1), lambda: [ModbusTcpTransport(port=0)]).start()
    try:
        yield st, st.transports[0].info()["port"]
    finally:
        st.stop()


@needs_socat
def test_5_6_pymodbus_client_over_a_socat_pty_pair(sim_rtu: tuple[ServiceThread, str]) -> None:
    st, path = sim_rtu
    client = ModbusSerialClient(path, baudrate=38400, timeout=2, retries=0)
    try:
        exercise(Pymodbus(client), st)
    finally:
        client.close()
    assert st.call(lambda: st.chain.get_param(1, 81)) == 1


def test_5_6_pymodbus_client_over_tcp(sim_tcp: tuple[ServiceThread, int]) -> None:
    st, port = sim_tcp
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
    try:
        exercise(Pymodbus(client), st)
    finally:
        client.close()
    assert st.call(lambda: st.chain.get_param(1, 81)) == 0   # the TCP door needs no K81


@needs_socat
@needs_mbpoll
def test_5_6_mbpoll_over_a_socat_pty_pair(sim_rtu: tuple[ServiceThread, str]) -> None:
    st, path = sim_rtu
    exercise(Mbpoll("-m", "rtu", "-b", "38400", "-P", "none", path), st)


@needs_mbpoll
def test_5_6_mbpoll_over_tcp(sim_tcp: tuple[ServiceThread, int]) -> None:
    st, port = sim_tcp
    exercise(Mbpoll("-m", "tcp", "-p", str(port), "127.0.0.1"), st)


@needs_socat
def test_5_6_6_com1_against_a_pymodbus_server_as_io_slave(tmp_path: Path) -> None:
    """Setting example 3 with the 5.6.7 addresses; the I/O slave is pymodbus' server."""
    with socat_pty_pair(tmp_path) as (slave_side, com1_side):
        slave = subprocess.Popen([sys.executable, str(Path(__file__).with_name(
            "modbus_io_slave.py")), slave_side, "38400"], stdout=subprocess.PIPE, text=True)
        st = ServiceThread(lambda: Chain(motors=3), lambda: [Com1Transport(com1_side)]).start()
        try:
            assert slave.stdout is not None and slave.stdout.readline().strip() == "ready"
            replies: list[str] = []
            st.call(st.chain.subscribe, lambda e: replies.append(e.text) if e.motor == 4 else None)
            st.call(st.chain.execute, "K79.3=200, K80.3=300, K84.3=1")

            def ask(line: str, expect: str | None = None) -> None:
                replies.clear()
                st.call(st.chain.execute, line)
                if expect is None:   # a write: wait until COM1 is free again
                    assert wait_for(lambda: st.call(lambda: st.chain.com1._pending) is None)
                else:
                    assert wait_for(lambda: replies == [expect]), (line, replies)

            ask("?70.4", "IN.4=1A04")                 # 5.6.6: the device's inputs, in hex
            ask("O.4=52481")                          # FC15: 0xCD01 to coils 300..315
            ask("?50.4", "OUT.4=CD01")                # FC01 reads back what the slave holds
            ask("F7.4")                               # FC05 at 306: coil 7 of 16 off
            ask("O2.4")                               # FC05 at 301
            ask("?50.4", "OUT.4=8F01")
            com1 = st.chain.com1
            assert st.call(lambda: (com1.timeouts, com1.errors, com1.exceptions)) == (0, 0, 0)
        finally:
            st.stop()
            slave.terminate()
            slave.wait(5)


def test_pymodbus_client_on_the_coolmuscle_url() -> None:
    """pymodbus opens ports with ``serial_for_url``, so it can drive an in-process chain."""
    import coolmuscle

    coolmuscle.register_url_handler()

    client = ModbusSerialClient("coolmuscle://?motors=2", baudrate=38400, timeout=2, retries=0)
    assert client.connect()
    try:
        port = client.socket
        port.write(b"K81.1=1, K84.2=-4\r")                  # COM0 to Modbus by text first
        assert port.read_until(b"K84.2=-4\r\n").endswith(b"K84.2=-4\r\n")
        assert not client.write_registers(200, [0, 777], device_id=4).isError()
        assert client.read_holding_registers(200, count=2, device_id=4).registers == [0, 777]
        assert client.read_holding_registers(200, count=2, device_id=1).registers == [0, 0]
        assert port.chain.get_register(2, "P", 0) == 777
    finally:
        client.close()


def test_modbus_tcp_units_follow_k81_and_k84() -> None:
    """Unit id = Modbus address; 255 and (while K81 = 0) 1 reach ID1; others are silent."""
    st = ServiceThread(lambda: Chain(motors=2), lambda: [ModbusTcpTransport(port=0)]).start()
    probe = bytes.fromhex("03 03 6A 00 02")            # K81 (K78+874)

    def ask(sock: socket.socket, unit: int) -> bytes:
        """The answer to ``unit``, or b"" when a following unit-255 probe answers first."""
        sock.sendall(bytes.fromhex("00 01 00 00 00 06") + bytes((unit,)) + probe
                     + bytes.fromhex("00 02 00 00 00 06 FF") + probe)
        got = b""
        while len(got) < 13 or got[-13:-11] != b"\x00\x02":
            got += sock.recv(100)
        return got[:-13]
    try:
        port = st.transports[0].info()["port"]
        with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
            assert ask(sock, 1) == bytes.fromhex("00 01 00 00 00 07 01 03 04 00 00 00 00")
            assert ask(sock, 2) == b""
            st.call(st.chain.execute, "K81.1=5, K84.2=-4")
            assert ask(sock, 1) == b""
            assert ask(sock, 5) == bytes.fromhex("00 01 00 00 00 07 05 03 04 00 00 00 05")
            assert ask(sock, 4) == bytes.fromhex("00 01 00 00 00 07 04 03 04 00 00 00 00")
            assert ask(sock, 0) == b""                 # broadcast: executed, no answer
    finally:
        st.stop()


@needs_socat
def test_5_6_1_serial_devices_follow_k20_k65_and_k82(tmp_path: Path) -> None:
    """COM0 runs at ID1's K20 and K82, COM1 at the final motor's K65 and K82.  A pty
    takes the baud rate but refuses parity bits: that must not stop the data."""
    import termios

    with socat_pty_pair(tmp_path / "0") as (com0, host), \
            socat_pty_pair(tmp_path / "1") as (com1, _device):
        st = ServiceThread(lambda: Chain(motors=2),
                           lambda: [ModbusRtuTransport(com0), Com1Transport(com1)]).start()
        try:
            com0_fd = st.transports[0].inner._dev.fd
            com1_fd = st.transports[1]._dev.fd
            assert termios.tcgetattr(com0_fd)[4] == termios.B38400
            st.call(st.chain.execute, "K82.1=1, K65.2=3, K82.2=2, K84.2=1")
            request = bytes.fromhex("01 03 00 C8 00 02 45 F5")
            with serial.Serial(host, 38400, timeout=2) as port:
                port.write(request)                  # the parity change is tried here
                assert port.read(9) == bytes.fromhex("01 03 04 00 00 00 00 FA 33")
                st.call(st.chain.execute, "?70.3")   # COM1 sends at K65 = 57.6 kbps
                assert wait_for(lambda: termios.tcgetattr(com1_fd)[4] == termios.B57600)
                st.call(st.chain.set_param, 1, 20, 4)
                port.write(request)                  # the motor switches to 115.2 kbps
                assert port.read(9) == bytes.fromhex("01 03 04 00 00 00 00 FA 33")
                assert termios.tcgetattr(com0_fd)[4] == termios.B115200
        finally:
            st.stop()
