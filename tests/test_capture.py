"""``coolmuscle capture`` with real clients and a simulator standing in for the motor
(docs/user-guide.md "coolmuscle capture").

The "real motor" is ``coolmuscle sim --machine heavy.toml`` (a heavier load, more
friction and a stopper that a move pushes against until the overload alarm), served on
TCP or on a pty; the relay and the sim are separate processes, as on a bench.  The
clients are pyserial on the relay's pty, the host library over ``--listen`` and
``coolmuscle term`` in tmux.  Each capture then replays with ``run --check`` against a
sim with that machine file with no difference, and fails against the motor alone.  The
sessions are events and queries at rest: a reply polled while the motor moves depends
on the instant, which wall-clock jitter moves (``coolmuscle compare`` takes those with
tolerances).

The byte tests use a plain TCP peer as the motor (exact bytes both ways, no CML): a
megabyte each way, a full file system.
"""

from __future__ import annotations

import os
import re
import resource
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import serial

from coolmuscle.tools.script import parse_script
from fixtures import Program, ServedSim, coolmuscle_env, wait_until

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "capture"
HEAVY = DATA / "heavy.toml"
PLAIN = DATA / "plain.toml"
ENV = coolmuscle_env()


@pytest.fixture
def procs() -> Iterator[list[Program]]:
    started: list[Program] = []
    yield started
    for proc in reversed(started):
        proc.close()


def start_sim(procs: list[Program], tmp: Path, *, pty: bool | Path = False) -> ServedSim:
    """The "real motor": ``sim --machine heavy.toml`` on TCP (port 0) or on a pty."""
    sim = ServedSim(tmp / "sim.log", "--machine", str(HEAVY), tcp=not pty, pty=pty)
    procs.append(sim)
    return sim


def start_capture(procs: list[Program], tmp: Path, *args: str) -> tuple[Program, str]:
    """``coolmuscle capture ARGS``; returns it and where the host program connects."""
    cap = Program(["capture", *args], tmp / "capture.log")
    procs.append(cap)
    where = cap.wait_for(r"capture ready: host program on (\S+?)(?: -> \S+)?;").group(1)
    return cap, where


def run_check(session: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "coolmuscle", "run", "--check", str(session),
                           *args], capture_output=True, text=True, timeout=120, env=ENV)


def script_bytes(session: Path, untils: bool = True) -> tuple[bytes, bytes]:
    """(bytes the script sends, bytes its ``<<`` lines expect).  ``untils=False`` leaves
    the ``@until`` lines out of the parse (thousands of long patterns of random bytes
    take seconds to compile; test_capture_writer.py checks them)."""
    text = session.read_text(encoding="utf-8")
    if not untils:
        text = "\n".join(line for line in text.split("\n") if not line.startswith("@until "))
    steps = parse_script(text).lines
    return (b"".join(s.data for s in steps if s.kind in ("send", "raw")),
            b"".join(s.data for s in steps if s.kind == "expect"))


class Host:
    """A host program's side of a pyserial port: lines out, everything read kept."""

    def __init__(self, port: Any) -> None:
        self.port = port
        self.sent = bytearray()
        self.received = bytearray()

    def send(self, data: bytes) -> None:
        self.port.write(data)
        self.sent += data

    def line(self, text: str) -> None:
        self.send(text.encode() + b"\r")

    def expect(self, text: str, timeout: float = 10) -> None:
        deadline = time.monotonic() + timeout
        while text.encode() not in self.received:
            if time.monotonic() > deadline:
                raise AssertionError(f"{text!r} not received: {bytes(self.received)!r}")
            self.received += self.port.read(max(1, self.port.in_waiting))

    def settle(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.received += self.port.read(max(1, self.port.in_waiting))


# -- the motor is the simulator ---------------------------------------------------
def test_pyserial_on_the_relay_pty_replays_with_no_difference(procs: list[Program],
                                                             tmp_path: Path) -> None:
    """Motor: sim on TCP.  Host: pyserial on ``--pty``.  A move in position, a move into
    the stopper until the overload alarm, queries at rest, a line typed a byte at a
    time.  Ctrl-C: exit 130, one line, the file complete; the link is gone."""
    url = start_sim(procs, tmp_path).url
    link, session = tmp_path / "motor", tmp_path / "session.cml"
    cap, _ = start_capture(procs, tmp_path, url, "--pty", str(link), "--out", str(session),
                           "--machine", str(HEAVY))
    assert "echo on" in cap.text and link.is_symlink()
    host = Host(serial.Serial(str(link), 38400, timeout=0.05))
    try:
        for line in ("S.1=100", "A.1=50", "P.1=3000", "^.1"):
            host.line(line)
        host.expect("Ux.1=8\r\n")                        # in position (K23 function 1)
        host.settle(0.3)
        host.line("?96.1")
        host.expect("Px.1=3000\r\n")
        host.line("P.1=8000")
        host.line("^.1")
        host.expect("Ux.1=4\r\n")                        # the stopper: overload alarm
        host.settle(0.2)
        for byte in b"?99.1\r":                          # typed a key at a time
            host.send(bytes([byte]))
            host.settle(0.02)
        host.expect("Ux.1=4\r\n?99.1\r\nUx.1=4\r\n")
        host.line("?96.1")
        host.expect("Px.1=6000\r\n")
        host.settle(0.2)
    finally:
        host.port.close()
    assert cap.signal(signal.SIGINT) == 130
    out = cap.text.splitlines()
    assert out[-1] == "coolmuscle: interrupted" and "Traceback" not in cap.text
    assert not link.exists() and not link.is_symlink()
    text = session.read_text()
    first, chain = text.splitlines()[:2]
    assert re.fullmatch(rf"# coolmuscle capture: port={re.escape(url)} baud=38400 "
                        r"parity=none echo=on started=\S+Z k20=0 k23=1", first)
    assert chain == f"# chain: firmware=cm2 machine={os.path.relpath(HEAVY, tmp_path)}"
    assert re.search(r"\n# end: sent=\d+ received=\d+ bytes_to_motor=\d+ "
                     r"bytes_from_motor=\d+ stopped=ctrl-c\n$", text)
    assert script_bytes(session) == (bytes(host.sent), bytes(host.received))
    replay = run_check(session)                          # the machine named in the header
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert re.match(r"coolmuscle: ok: \d+ expectation\(s\) matched", replay.stdout)
    alone = run_check(session, "--machine", str(PLAIN))  # the motor alone: no stopper,
    assert alone.returncode == 1, alone.stdout               # so no alarm comes
    assert "@until '^Ux\\\\.1=4$' timed out" in alone.stderr, alone.stderr


def test_host_library_through_listen_with_the_sim_on_a_pty(procs: list[Program],
                                                         tmp_path: Path) -> None:
    """Motor: sim on a pty (a serial device to the relay).  Host: ``coolmuscle.connect``
    over ``--listen``; ``--once`` ends the capture when it disconnects (exit 0)."""
    motor = tmp_path / "simport"
    start_sim(procs, tmp_path, pty=motor)
    session = tmp_path / "lib.cml"
    cap, where = start_capture(procs, tmp_path, str(motor), "--listen", "0", "--once",
                               "--out", str(session))
    import coolmuscle
    from coolmuscle.errors import AlarmError
    with coolmuscle.connect(where) as m:
        m.move_to(2500, speed=100, accel=50)
        m.wait_in_position(timeout=10)
        time.sleep(0.3)
        assert m.position == 2500
        m.move_to(9000, speed=100, accel=50)
        with pytest.raises(AlarmError):                    # into the stopper at 6000
            m.wait_in_position(timeout=15)
        time.sleep(0.2)
        assert m.position == 6000
    assert cap.proc.wait(timeout=20) == 0
    assert "capture ended (host-closed)" in cap.text
    assert session.read_text().endswith(" stopped=host-closed\n")
    replay = run_check(session, "--machine", str(HEAVY))
    assert replay.returncode == 0, replay.stdout + replay.stderr


@pytest.mark.peer
def test_term_in_tmux_through_the_relay(procs: list[Program], tmp_path: Path) -> None:
    """``coolmuscle term`` as a person uses it, through the relay."""
    from test_term import Pane, term_env
    url = start_sim(procs, tmp_path).url
    session = tmp_path / "term.cml"
    cap, where = start_capture(procs, tmp_path, url, "--listen", "0", "--once", "--out",
                               str(session))
    pane = Pane([sys.executable, "-m", "coolmuscle", "term", where], term_env(tmp_path))
    try:
        pane.prompt()
        for line in ("S.1=200", "A.1=100", "P.1=4000", "^.1"):
            pane.type(line)
            pane.prompt()
        pane.wait(r"Ux\.1=8")
        time.sleep(0.3)
        pane.type("?96.1")
        pane.wait(r"Px\.1=4000")
        pane.prompt()
        pane.type(":quit")
        assert pane.exit_status() == 0
    finally:
        pane.close()
    assert cap.proc.wait(timeout=20) == 0
    replay = run_check(session, "--machine", str(HEAVY))
    assert replay.returncode == 0, replay.stdout + replay.stderr + session.read_text()


# -- the motor is a plain TCP peer: exact bytes ---------------------------------------
class Peer:
    """A TCP peer standing in for the motor: keeps what it gets, sends what it is told;
    ``echo`` sends back every byte it gets."""

    def __init__(self, echo: bool = False) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.url = f"socket://127.0.0.1:{self.server.getsockname()[1]}"
        self.echo = echo
        self.received = bytearray()
        self.conn: socket.socket | None = None
        self.connected = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        conn, _ = self.server.accept()
        self.conn = conn
        self.connected.set()
        while data := conn.recv(65536):
            self.received += data
            if self.echo:
                conn.sendall(data)

    def close(self) -> None:
        if self.conn is not None:
            try:
                self.conn.shutdown(socket.SHUT_RDWR)     # FIN now (and wakes our reader)
            except OSError:
                pass
            self.conn.close()
        self.server.close()


def _read_exactly(read: Callable[[int], bytes], size: int, timeout: float = 60) -> bytes:
    got = bytearray()
    deadline = time.monotonic() + timeout
    while len(got) < size and time.monotonic() < deadline:
        got += read(size - len(got))
    return bytes(got)


@pytest.mark.parametrize("side", ["listen", "pty"])
def test_a_megabyte_each_way_at_once_loses_no_byte(side: str, procs: list[Program],
                                                   tmp_path: Path) -> None:
    """1 MiB of random bytes each way at the same time: both arrive exactly, and the
    file says exactly both (its ``<<`` lines and its sent lines).  SIGTERM ends it
    (143, ``stopped=sigterm``)."""
    peer = Peer()
    session = tmp_path / "burst.cml"
    where_arg = ["--listen", "0"] if side == "listen" else ["--pty", str(tmp_path / "link")]
    cap, where = start_capture(procs, tmp_path, peer.url, *where_arg, "--no-probe",
                               "--out", str(session))
    up, down = os.urandom(1 << 20), os.urandom(1 << 20)
    port = serial.serial_for_url(where, timeout=0.5)
    try:
        assert peer.connected.wait(10) and peer.conn is not None
        if side == "listen":      # the motor's bytes reach a host program once taken
            cap.wait_for(r"host program connected from ", timeout=30)
        writer = threading.Thread(target=port.write, args=(up,), daemon=True)
        writer.start()
        assert peer.conn is not None
        sender = threading.Thread(target=peer.conn.sendall, args=(down,), daemon=True)
        sender.start()
        got = _read_exactly(lambda n: port.read(min(n, 65536)), len(down))
        writer.join(60)
        wait_until(lambda: len(peer.received) >= len(up), 60, 0.05)
    finally:
        port.close()
    assert got == down
    assert bytes(peer.received) == up
    time.sleep(0.3)                                   # the writer thread catches up
    assert cap.signal(signal.SIGTERM) == 128 + signal.SIGTERM
    assert cap.text.splitlines()[-1] == "coolmuscle: stopped (SIGTERM)"
    text = session.read_text()
    assert text.startswith("# coolmuscle capture: ") and " echo=unknown " in text
    assert text.endswith(f" bytes_to_motor={len(up)} bytes_from_motor={len(down)} "
                         "stopped=sigterm\n")
    assert script_bytes(session, untils=False) == (up, down)
    peer.close()


def _tiny_file_system(path: Path) -> Callable[[], None] | None:
    """A 32 KiB tmpfs at ``path`` (root only); returns how to unmount it."""
    if os.geteuid() != 0:
        return None
    path.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=32k", "tmpfs", str(path)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        return None
    return lambda: subprocess.run(["umount", str(path)], check=True)


def test_a_full_file_system_says_so_and_the_relay_goes_on(procs: list[Program],
                                                         tmp_path: Path) -> None:
    """The capture file on a 32 KiB tmpfs (root; otherwise a 32 KiB file size limit,
    RLIMIT_FSIZE, which fails the same way with EFBIG): one line says the file stopped
    growing, every byte still goes both ways, and the file holds whole lines only."""
    full = tmp_path / "full"
    unmount = _tiny_file_system(full)
    limit: dict[str, Any] = {}
    if unmount is None:
        print("not root: a file size limit stands in for the full file system")
        full.mkdir()

        def small_files() -> None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (32 << 10, 32 << 10))
        limit["preexec_fn"] = small_files
    try:
        peer = Peer(echo=True)
        session = full / "s.cml"
        cap = Program(["capture", peer.url, "--listen", "0", "--no-probe", "--out",
                    str(session)], tmp_path / "capture.log", **limit)
        procs.append(cap)
        where = cap.wait_for(r"host program on (\S+);").group(1)
        lines = b"".join(f"?96.{n % 15 + 1}\r".encode() for n in range(4000))
        with serial.serial_for_url(where, timeout=0.5) as port:
            for start in range(0, len(lines), 600):      # a host program's own pace
                chunk = lines[start:start + 600]
                port.write(chunk)
                assert _read_exactly(port.read, len(chunk), timeout=20) == chunk
        assert peer.received == lines
        assert cap.signal(signal.SIGINT) == 130
        said = [line for line in cap.text.splitlines() if "stopped growing" in line]
        why = "File too large" if unmount is None else "No space left on device"
        assert len(said) == 1 and why in said[0] and "the relay goes on" in said[0], cap.text
        data = session.read_bytes()
        assert data.endswith(b"\n") and len(data) <= 32 << 10 and b"# end:" not in data
        sent, _ = script_bytes(session)
        assert lines.startswith(sent) and len(sent) > 1000
        peer.close()
    finally:
        for proc in procs:
            proc.close()
        if unmount is not None:
            unmount()


# -- bad input: one line, exit 2, nothing written -----------------------------------------
def _capture_bad(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    """``coolmuscle capture ARGS`` in this process (as tests/test_cli.py runs commands)."""
    from coolmuscle.tools.cli import app
    with pytest.raises(SystemExit) as info:
        app.main(["capture", *args])
    out, err = capsys.readouterr()
    code = info.value.code
    return (code if isinstance(code, int) else 0 if code is None else 1), out + err


@pytest.mark.parametrize("args, says", [
    (["/dev/ttyNOSUCH", "--listen", "0", "--out", "{tmp}/s.cml"],
     "cannot open the motor's port /dev/ttyNOSUCH: No such file or directory"),
    (["socket://127.0.0.1:{closed}", "--listen", "0", "--out", "{tmp}/s.cml"],
     "cannot open the motor's port socket://127.0.0.1:{closed}: Connection refused"),
    (["bogus://x", "--listen", "0", "--out", "{tmp}/s.cml"], "protocol 'bogus' not known"),
    (["coolmuscle://", "--listen", "0", "--out", "{tmp}/nodir/s.cml"], "no such directory"),
    (["coolmuscle://", "--listen", "0", "--out", "{tmp}"], "a directory, not a file"),
    (["coolmuscle://", "--out", "{tmp}/s.cml"], "give one of --listen"),
    (["coolmuscle://", "--listen", "0", "--pty", "{tmp}/l", "--out", "{tmp}/s.cml"],
     "give one of --listen"),
    (["coolmuscle://", "--pty", "{tmp}/l", "--once", "--out", "{tmp}/s.cml"],
     "use it with --listen"),
    (["coolmuscle://", "--listen", "0", "--baud", "12345", "--out", "{tmp}/s.cml"],
     "--baud 12345: the motor's rates are 9600"),
    (["coolmuscle://", "--listen", "host:port:x", "--out", "{tmp}/s.cml"], "--listen: bad"),
    (["coolmuscle://", "--pty", "{tmp}/afile", "--out", "{tmp}/s.cml"],
     "exists and is not a symlink"),
    (["coolmuscle://", "--listen", "0", "--machine", "{tmp}/none.toml", "--out",
      "{tmp}/s.cml"], "--machine {tmp}/none.toml: no such file"),
    (["coolmuscle://", "--listen", "0", "--machine", "{tmp}/bad.toml", "--out",
      "{tmp}/s.cml"], "inertai"),
    (["coolmuscle://", "--listen", "0", "--machine", "{tmp}/my machine.toml", "--out",
      "{tmp}/s.cml"], "use a path without spaces"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(
        args: list[str], says: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        closed_port: int) -> None:
    (tmp_path / "afile").write_text("not a link\n")
    (tmp_path / "bad.toml").write_text("[[axis]]\n[axis.load]\ninertai = 1\n")
    (tmp_path / "my machine.toml").write_text(PLAIN.read_text())
    before = sorted(p.name for p in tmp_path.iterdir())
    code, text = _capture_bad(capsys, *(a.format(tmp=tmp_path, closed=closed_port)
                                        for a in args))
    assert code == 2, text
    assert text.count("\n") == 1 and text.startswith("coolmuscle: error: "), text
    assert says.format(tmp=tmp_path, closed=closed_port) in text
    assert sorted(p.name for p in tmp_path.iterdir()) == before      # nothing written


def test_a_link_that_breaks_says_so_in_one_line_and_the_file_is_complete(
        procs: list[Program], tmp_path: Path) -> None:
    """The motor's end closes: what it said last still reaches the host program, on a
    pty (a small buffer: the relay holds the rest) read late."""
    peer = Peer(echo=True)
    session = tmp_path / "s.cml"
    cap, where = start_capture(procs, tmp_path, peer.url, "--pty", str(tmp_path / "link"),
                               "--no-probe", "--out", str(session))
    last = os.urandom(1 << 20)
    with serial.serial_for_url(where, timeout=0.5) as port:
        port.write(b"?96.1\r")
        assert _read_exactly(port.read, 6) == b"?96.1\r"
        assert peer.conn is not None
        peer.conn.sendall(last)                          # its last words, then
        peer.close()                                     # the other end closes
        time.sleep(0.3)                                  # the program reads them late:
        assert _read_exactly(port.read, len(last)) == last     # they still reach it
        assert cap.proc.wait(timeout=20) == 1
    errors = [line for line in cap.text.splitlines() if "error" in line]
    assert errors == [f"coolmuscle: error: the link to {peer.url} broke: closed by the "
                      "other end"]
    assert session.read_text().endswith(" stopped=link-broken\n")
