"""``coolmuscle sim`` with the Modbus front ends, as a real subprocess (docs/modbus.md)."""

from __future__ import annotations

import os
import signal
import socket
import sys
from pathlib import Path
from typing import Any

import pexpect
import pytest
import serial

from coolmuscle.tools.cli import app as cli
from modbus_support import crc, frame

SRC = str(Path(__file__).resolve().parents[1] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC, "COLUMNS": "200"}
ENV.pop("COOLMUSCLE_DEBUG", None)


def test_sim_serves_modbus_rtu_tcp_and_com1_and_says_com0_speaks_modbus() -> None:
    child = pexpect.spawn(sys.executable, ["-m", "coolmuscle", "sim", "--no-state", "--motors",
                                           "2", "--modbus-rtu", "pty", "--modbus-tcp", "0",
                                           "--com1", "pty"],
                          env=ENV, timeout=15, encoding="utf-8")
    try:
        child.expect(r"virtual CM2 ID1-ID2 ready")
        child.expect(r"modbus-rtu: (/dev/pts/\d+) \(station 1\)\s+modbus-tcp: 127\.0\.0\.1:(\d+)"
                     r"\s+com1: (/dev/pts/\d+)")
        rtu_path, tcp_port, com1_path = child.match.groups()
        child.expect(r"note: K81\.1=1: COM0 speaks Modbus RTU; no state is saved")
        with serial.Serial(rtu_path, 38400, timeout=3) as port:          # K81 over RTU
            port.write(frame("01 03 03 6A 00 02"))
            assert port.read(9) == frame("01 03 04 00 00 00 01")
        with socket.create_connection(("127.0.0.1", int(tcp_port)), timeout=3) as sock:
            sock.sendall(bytes.fromhex("00 07 00 00 00 06 01 04 00 20 00 02"))  # Ux ID1, ID2
            assert sock.recv(100) == bytes.fromhex("00 07 00 00 00 07 01 04 04 00 08 00 08")
        with serial.Serial(com1_path, 38400, timeout=3) as io_slave:
            with socket.create_connection(("127.0.0.1", int(tcp_port)), timeout=3) as sock:
                # K84.2 := 1 through the CML command input of ID1 (K78+102).
                text = b"K84.2=1\r"
                sock.sendall(bytes.fromhex("00 08 00 00 00 0F 01 10 00 66 00 04 08") + text)
                assert sock.recv(100) == bytes.fromhex("00 08 00 00 00 06 01 10 00 66 00 04")
                sock.sendall(bytes.fromhex("00 09 00 00 00 0F 01 10 00 66 00 04 08")
                             + b"?70.3\r\x00\x00")
                assert sock.recv(100) == bytes.fromhex("00 09 00 00 00 06 01 10 00 66 00 04")
            request = io_slave.read(8)
            assert request == frame("01 02 00 00 00 10")
            answer = bytes.fromhex("01 02 02 00 05")
            io_slave.write(answer + crc(answer))
        child.kill(signal.SIGTERM)
        child.expect("coolmuscle: stopped")
        child.expect(pexpect.EOF)
        child.close()
        assert child.exitstatus == 0
    finally:
        if child.isalive():
            child.terminate(force=True)


def run_cli(capsys: Any, *args: str) -> tuple[int, str]:
    with pytest.raises(SystemExit) as stop:
        cli.main(list(args))
    return int(stop.value.code or 0), capsys.readouterr().err


@pytest.mark.parametrize("args, code, message", [
    (["--firmware", "cm1", "--modbus-tcp", "0"], 2, "cm1 has no Modbus"),
    (["--modbus-tcp", "host:port"], 2, "--modbus-tcp: bad TCP address"),
    (["--modbus-rtu", "/nonexistent/tty"], 1, "cannot open serial port /nonexistent/tty"),
    (["--com1", "/nonexistent/tty"], 1, "cannot open serial port /nonexistent/tty"),
])
def test_sim_modbus_option_errors_are_one_line(capsys: Any, args: list[str], code: int,
                                               message: str) -> None:
    got, err = run_cli(capsys, "sim", "--no-state", *args)
    assert got == code and message in err, err
    assert err.count("\n") == 1 and "Traceback" not in err
