"""``coolmuscle capture`` keeps its memory bounded and stops at once (docs/twin.md,
docs/reliability.md "Bounds").

A line without a line end, however long, is recorded in pieces; the bytes waiting to
be recorded and those waiting for the host program are bounded, and a side whose peer
does not take what it is sent is no longer read (back pressure); Ctrl-C ends the
capture within a second with the file complete (its ``# end:`` line).  The motor is a
plain TCP peer; the capture runs as its own process, whose peak resident memory
(``VmHWM``) is read before it is stopped.
"""

from __future__ import annotations

import signal
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial

from fixtures import Program, wait_until

MIB = 1 << 20
#: A MiB of every byte but CR and LF (no line end; most bytes written escaped).
NO_LINE_END = (bytes(b for b in range(256) if b not in (10, 13)) * 4370)[:MIB]
#: Peak resident memory a capture may reach whatever it relays (the interpreter and
#: coolmuscle's imports take about 40 MiB of it).
PEAK_BOUND_MIB = 120


class Motor:
    """A TCP peer standing in for the motor: counts what it gets (keeps nothing),
    sends what it is told, in a thread of its own."""

    def __init__(self) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.url = f"socket://127.0.0.1:{self.server.getsockname()[1]}"
        self.received = 0
        self.conn: socket.socket | None = None
        self.connected = threading.Event()
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        conn, _ = self.server.accept()
        self.conn = conn
        self.connected.set()
        try:
            while data := conn.recv(1 << 16):
                self.received += len(data)
        except OSError:
            pass

    def send_in_background(self, data: bytes, times: int) -> threading.Thread:
        """Send ``data`` ``times`` times from a thread (it may block: back pressure)."""
        def send() -> None:
            assert self.conn is not None
            try:
                for _ in range(times):
                    self.conn.sendall(data)
            except OSError:
                pass
        thread = threading.Thread(target=send, daemon=True)
        thread.start()
        return thread

    def close(self) -> None:
        for sock in (self.conn, self.server):
            if sock is not None:
                sock.close()


# 64 MiB through a relay and a sim: about 15 s on a loaded 2-CPU machine, more beside
# the rest of the suite
pytestmark = pytest.mark.timeout(360)


@pytest.fixture
def motor() -> Iterator[Motor]:
    peer = Motor()
    yield peer
    peer.close()


def stop_and_measure(cap: Program) -> tuple[float, float]:
    """SIGINT (Ctrl-C) and wait: exit status 130; the seconds it took and the peak
    resident memory of the whole run in MiB (``VmHWM``, read every 2 ms until the
    process is gone, so the stop itself counts too; the kernel's ``ru_maxrss`` of a
    child would count the forked copy of this test process before its exec)."""
    peak = [0.0]

    def watch() -> None:
        status = Path(f"/proc/{cap.pid}/status")
        while True:
            try:
                text = status.read_text()
            except OSError:
                return
            for line in text.splitlines():
                if line.startswith("VmHWM:"):
                    peak[0] = max(peak[0], int(line.split()[1]) / 1024)
            time.sleep(0.002)
    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    time.sleep(0.05)
    started = time.monotonic()
    assert cap.signal(signal.SIGINT, timeout=60) == 130, cap.text
    took = time.monotonic() - started
    watcher.join(5)
    return took, peak[0]


def start(tmp: Path, motor: Motor, session: Path) -> tuple[Program, str]:
    cap = Program(["capture", motor.url, "--listen", "0", "--no-probe", "--out",
                   str(session)], tmp / "capture.log")
    where = cap.wait_for(r"host program on (\S+);").group(1)
    return cap, where


def end_line(session: Path) -> str:
    with session.open("rb") as fh:
        fh.seek(-4096, 2)
        return fh.read().decode().splitlines()[-1]


def test_a_64_mib_line_from_the_host_is_recorded_in_pieces(tmp_path: Path,
                                                           motor: Motor) -> None:
    session = tmp_path / "long.cml"
    cap, where = start(tmp_path, motor, session)
    try:
        line = NO_LINE_END
        with serial.serial_for_url(where, timeout=1) as port:
            for _ in range(64):
                port.write(line)
            assert wait_until(lambda: motor.received == 64 * MIB, 120, 0.05), motor.received
        time.sleep(0.5)                                 # the file catches up
        took, peak = stop_and_measure(cap)
    finally:
        cap.close()
    assert peak < PEAK_BOUND_MIB, f"peak {peak:.0f} MiB"
    print(f"peak {peak:.0f} MiB, stopped in {took:.2f} s")
    assert took < 2.0, took
    assert end_line(session).startswith("# end: sent=") and \
        f"bytes_to_motor={64 * MIB} " in end_line(session)
    with session.open() as fh:
        pieces = [row for row in fh if row.startswith("@send ")]
    assert len(pieces) >= 1024 and max(len(row) for row in pieces) < 4 * 65536 + 10


def test_a_64_mib_line_from_the_motor_is_recorded_in_pieces(tmp_path: Path,
                                                            motor: Motor) -> None:
    session = tmp_path / "long.cml"
    cap, where = start(tmp_path, motor, session)
    try:
        with serial.serial_for_url(where, timeout=1) as port:
            assert motor.connected.wait(10)
            # what the motor sends while no host program is attached is recorded, not
            # relayed (a serial port with nobody listening): the connect returns when
            # the kernel accepted it, the capture takes it a moment later
            cap.wait_for(r"host program connected from ", timeout=30)
            motor.send_in_background(NO_LINE_END, 64)
            got, deadline = 0, time.monotonic() + 120
            while got < 64 * MIB and time.monotonic() < deadline:
                got += len(port.read(1 << 20))
            assert got == 64 * MIB
        time.sleep(0.5)
        took, peak = stop_and_measure(cap)
    finally:
        cap.close()
    assert peak < PEAK_BOUND_MIB, f"peak {peak:.0f} MiB"
    print(f"peak {peak:.0f} MiB, stopped in {took:.2f} s")
    assert took < 2.0, took
    assert f"bytes_from_motor={64 * MIB} " in end_line(session)
    with session.open() as fh:
        pieces = [row for row in fh if row.startswith("<< ")]
    assert len(pieces) >= 1024 and max(len(row) for row in pieces) < 4 * 65536 + 10


def test_a_host_that_never_reads_holds_the_motor_back_and_ctrl_c_is_prompt(
        tmp_path: Path, motor: Motor) -> None:
    """200 MiB from the motor to a host program that reads nothing: the capture stops
    reading the motor once its bounded queues are full (the motor's sends block), its
    memory stays bounded, and Ctrl-C ends it within a second with the file whole."""
    session = tmp_path / "stuck.cml"
    cap, where = start(tmp_path, motor, session)
    address, port = where.removeprefix("socket://").rsplit(":", 1)
    host = socket.create_connection((address, int(port)))
    host.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    try:
        assert motor.connected.wait(10)
        chunk = b"Ux.1=8\r\n" * (MIB // 8)
        sender = motor.send_in_background(chunk, 200)
        time.sleep(3.0)
        assert sender.is_alive()                     # held back: not all of it was taken
        took, peak = stop_and_measure(cap)
    finally:
        host.close()
        cap.close()
    assert peak < PEAK_BOUND_MIB, f"peak {peak:.0f} MiB"
    print(f"peak {peak:.0f} MiB, stopped in {took:.2f} s")
    assert took < 2.0, took
    assert end_line(session).endswith(" stopped=ctrl-c")
