"""``coolmuscle term`` as a person uses it: tmux types the keys and reads the screen.

The terminal runs in a real tmux pane (its own tmux server socket); the test types
lines, arrow keys and Ctrl-D with ``send-keys`` and reads the rendered screen with
``capture-pane`` (``-e`` keeps the colours).  The motor is the simulator behind TCP in
this process, or the in-process ``coolmuscle://`` in the terminal's own process.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport
from fixtures import wait_until

pytestmark = pytest.mark.peer

ROOT = Path(__file__).resolve().parents[1]
GREEN, CYAN, RED, YELLOW = "\x1b[32m", "\x1b[36m", "\x1b[31m", "\x1b[33m"


class Pane:
    """A tmux pane running one command (a private tmux server)."""

    def __init__(self, command: list[str], env: dict[str, str]) -> None:
        if shutil.which("tmux") is None:
            raise RuntimeError("tmux is required (scripts/test installs it)")
        self.socket = f"cm-{uuid.uuid4().hex[:8]}"
        self.status_file = Path(env["HOME"]) / f"exit-{self.socket}"
        # the shell records the exit status: tmux sometimes marks a pane dead before it
        # has reaped the process (under load its #{pane_dead_status} stays empty)
        line = "env " + " ".join(f"{k}={shlex.quote(v)}" for k, v in env.items()) + " " + \
            " ".join(shlex.quote(part) for part in command) + \
            f"; echo $? > {shlex.quote(str(self.status_file))}"
        self.tmux("new-session", "-d", "-s", "t", "-x", "160", "-y", "200", line)
        self.tmux("set-option", "-t", "t", "remain-on-exit", "on")

    def tmux(self, *args: str) -> str:
        out = subprocess.run(["tmux", "-L", self.socket, *args], capture_output=True,
                             text=True, timeout=10)
        return out.stdout

    def screen(self, colours: bool = False) -> str:
        return self.tmux("capture-pane", "-p", "-J", *(["-e"] if colours else []), "-t", "t")

    def wait(self, pattern: str, timeout: float = 10, colours: bool = False) -> str:
        end = time.monotonic() + timeout
        while True:
            text = self.screen(colours)
            if re.search(pattern, text, re.MULTILINE):
                return text
            if time.monotonic() > end:
                raise AssertionError(f"{pattern!r} not on the screen:\n{text}")
            time.sleep(0.05)

    def prompt(self, timeout: float = 10) -> None:
        """Wait until the prompt is the last line (a person types when it is there)."""
        end = time.monotonic() + timeout
        while True:
            lines = [line for line in self.screen().splitlines() if line.strip()]
            if lines and lines[-1].strip() == "ID1>":
                return
            if time.monotonic() > end:
                raise AssertionError(f"no prompt:\n{self.screen()}")
            time.sleep(0.05)

    def type(self, text: str, enter: bool = True) -> None:
        self.tmux("send-keys", "-t", "t", "-l", text)
        if enter:
            self.tmux("send-keys", "-t", "t", "Enter")

    def keys(self, *keys: str) -> None:
        self.tmux("send-keys", "-t", "t", *keys)

    def exit_status(self, timeout: float = 10) -> int:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.status_file.exists() and self.status_file.read_text().strip():
                return int(self.status_file.read_text())
            time.sleep(0.05)
        raise AssertionError(f"the terminal did not end:\n{self.screen()}")

    def close(self) -> None:
        self.tmux("kill-server")


def term_env(tmp: Path) -> dict[str, str]:
    return {"PYTHONPATH": str(ROOT / "src"), "TERM": "xterm-256color",
            "XDG_STATE_HOME": str(tmp / "state"), "PROMPT_TOOLKIT_NO_CPR": "1",
            "PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(tmp)}


@pytest.fixture
def served() -> Iterator[ServiceThread]:
    service = ServiceThread(lambda: Chain(), lambda: [TcpTransport(port=0)], scale=4)
    service.start()
    yield service
    service.stop()


def line_with(screen: str, text: str) -> str:
    return next(line for line in screen.splitlines() if text in line)


def test_term_as_a_person_uses_it(served: ServiceThread, tmp_path: Path) -> None:
    port = served.transports[0].info()["port"]
    pane = Pane([sys.executable, "-m", "coolmuscle", "term", f"socket://127.0.0.1:{port}"],
                term_env(tmp_path))
    try:
        pane.prompt()
        pane.type("?96.1")
        screen = pane.wait(r"Px\.1=0", colours=True)
        assert GREEN in line_with(screen, "Px.1=0")                   # a reply: green
        assert "?96.1" not in screen.split("ID1> ?96.1")[1]            # no second echo
        pane.prompt()
        pane.type("K23.1=19")                                          # reports + messages
        pane.type("P.1=3000")
        pane.type("^.1")
        screen = pane.wait(r"Ux\.1=8  \(in position\)", colours=True)  # came by itself
        assert CYAN in line_with(screen, "Ux.1=8")
        served.call(lambda: served.chain.set_input(1, 3, True))        # someone flips input 3
        pane.wait(r"IN\.1=04")                                         # shown as it arrives
        pane.prompt()
        pane.type("hello")
        screen = pane.wait(r"error01\.1: syntax error!!", colours=True)
        assert RED in line_with(screen, "error01.1")
        pane.prompt()
        pane.keys("Up")                                                # history
        pane.wait(r"^ID1> hello\s*$")
        pane.keys("C-u")
        pane.type(f":send {ROOT / 'examples' / '2.2-program-bank.cml'}")
        screen = pane.wait(r"sent 12 line\(s\) of 2.2-program-bank.cml; banks B1.1 verified",
                           timeout=20, colours=True)
        assert YELLOW in line_with(screen, "banks B1.1 verified")
        pane.prompt()
        pane.type(":save")
        pane.wait(r"saved\.1")
        pane.prompt()
        pane.type(":help")
        pane.wait(r"commands: :send FILE.cml")
        pane.prompt()
        pane.keys("C-d")
        assert pane.exit_status() == 0
    finally:
        pane.close()
    history = (tmp_path / "state" / "coolmuscle" / "term_history").read_text()
    assert "+?96.1" in history and "+hello" in history
    assert served.call(lambda: served.chain.execute("?1.1")) == ["S1.1, A1.1, P1.1", "T1.1",
                                                                 "P2.1"]


def logged(log: Path, text: str, timeout: float = 10.0) -> None:
    """Wait until the session log holds ``text``."""
    if not wait_until(lambda: text in (log.read_text() if log.exists() else ""), timeout):
        raise AssertionError(f"{text!r} not in the log:\n{log.read_text()}")


def test_a_logged_session_replays_as_a_golden_transcript(tmp_path: Path) -> None:
    log = tmp_path / "session.cml"
    pane = Pane([sys.executable, "-m", "coolmuscle", "term", "coolmuscle://",
                 "--log", str(log)], term_env(tmp_path))
    try:
        pane.prompt()
        for line in ("K23.1=17", "S.1=200", "A.1=1000", "P.1=2500", "^.1"):
            pane.type(line)       # the echo logged before the next line (as a person types;
            logged(log, f"<< {line}\\r\\n")     # on a loaded machine lines overtook it)
        pane.wait(r"Ux\.1=8")
        time.sleep(0.4)                                   # a person reads, then asks
        pane.prompt()
        pane.type("?96.1")
        pane.wait(r"Px\.1=2500")
        pane.prompt()
        pane.type("K44.1=0")
        pane.wait(r"error00\.1: Out Of Range!!")
        pane.prompt()
        pane.type(":quit")
        assert pane.exit_status() == 0
    finally:
        pane.close()
    text = log.read_text()
    assert "^.1\n<< ^.1\\r\\n\n@until ^Ux\\.1=8$" in text and "\n@wait 0." in text
    out = subprocess.run([sys.executable, "-m", "coolmuscle", "run", "--check", str(log)],
                         capture_output=True, text=True, timeout=60, env=term_env(tmp_path))
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.startswith("coolmuscle: ok: 10 expectation(s) matched")


def test_a_port_that_cannot_be_opened_is_one_line(tmp_path: Path, closed_port: int) -> None:
    url = f"socket://127.0.0.1:{closed_port}"
    out = subprocess.run([sys.executable, "-m", "coolmuscle", "term", url],
                         capture_output=True, text=True, timeout=60, env=term_env(tmp_path))
    assert out.returncode == 1
    assert out.stderr.startswith(f"coolmuscle: error: cannot open {url}")


def test_a_closed_connection_ends_the_terminal_at_once(tmp_path: Path) -> None:
    """The motor's side closes the connection while the person sits at the prompt: the
    terminal says so in red straight away and ends (exit status 1), before anything
    typed could be lost."""
    import socket
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    pane = Pane([sys.executable, "-m", "coolmuscle", "term",
                 f"socket://127.0.0.1:{server.getsockname()[1]}"], term_env(tmp_path))
    try:
        server.settimeout(10)
        conn, _ = server.accept()
        pane.prompt()
        conn.close()
        screen = pane.wait(r"connection lost: .*socket disconnected; the terminal ends",
                           colours=True)
        assert RED in line_with(screen, "connection lost")
        assert pane.exit_status() == 1
    finally:
        pane.close()
        server.close()
