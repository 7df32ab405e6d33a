"""``coolmuscle term``'s colon commands and its connection, without a screen: ``:motor``
takes a motor ID of the chain (1..15, cml-users-guide.txt 1.1) that answers and says
why it refuses another; a lost connection is said at once and ends the terminal."""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import sys
import threading
from typing import Any

import pytest

from coolmuscle import connect_async
from coolmuscle.errors import TransportError
from coolmuscle.tools.term import terminal as term
from fixtures import wait_until_async


@pytest.mark.parametrize("motors, arg, motor, style", [
    (2, "2", 2, "info"), (1, "2", 1, "error"), (2, "0", 1, "error"), (2, "16", 1, "error")])
def test_motor_command_takes_a_motor_of_the_chain(monkeypatch: Any, motors: int, arg: str,
                                                  motor: int, style: str) -> None:
    shown: list[tuple[str, str]] = []

    async def session() -> int:
        async with await connect_async(f"coolmuscle://?mode=fast&motors={motors}") as client:
            terminal = term.Terminal(client, "coolmuscle://",
                                     show=lambda text, kind: shown.append((text, kind)))
            assert await terminal.command(f"motor {arg}") is True
            return terminal.motor
    assert asyncio.run(session()) == motor
    assert shown and shown[-1][1] == style
    if (motors, arg) == (1, "2"):
        assert shown[-1][0] == "motor: ID2 does not answer (no reply to ?99.2): still ID1"


def test_a_closed_connection_is_noticed_before_the_next_line(monkeypatch: Any) -> None:
    """The peer closes the connection: the terminal says so at once (red) and the next
    line typed is refused, not written into the dead socket (the first write to a
    closed TCP peer "succeeds": it used to be lost silently, only the second said
    ``Broken pipe``)."""
    shown: list[tuple[str, str]] = []
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    accepted = threading.Event()

    def peer() -> None:
        conn, _ = server.accept()
        accepted.set()
        conn.close()
    thread = threading.Thread(target=peer, daemon=True)
    thread.start()

    async def session() -> tuple[bool, BaseException | None]:
        client = await connect_async(f"socket://127.0.0.1:{server.getsockname()[1]}",
                                     timeout=0.5, firmware="cm2")
        terminal = term.Terminal(client, "socket://",
                                 show=lambda text, kind: shown.append((text, kind)))
        client.add_failure_listener(terminal.connection_lost)
        try:
            for _ in range(200):                  # the reader sees the close
                if terminal.lost is not None:
                    break
                await asyncio.sleep(0.01)
            going_on = await terminal.handle("?96.1")
            with pytest.raises(TransportError):
                client.write_line("?96.1")
            return going_on, terminal.lost
        finally:
            await client.close()
    try:
        going_on, lost = asyncio.run(asyncio.wait_for(session(), 20))
    finally:
        thread.join(2)
        server.close()
    assert accepted.is_set()
    assert going_on is False and isinstance(lost, TransportError)
    assert shown == [("connection lost: cannot read from the port: read failed: socket "
                      "disconnected; the terminal ends", "error")]


class _WatchedInput:
    """Standard input from a pipe that says when the terminal reads it."""

    def __init__(self, stream: Any) -> None:
        self.stream = stream
        self.reading = threading.Event()

    def readline(self) -> str:
        self.reading.set()
        return str(self.stream.readline())

    def isatty(self) -> bool:
        return False


def test_a_stopped_plain_session_ends_while_its_input_is_silent(monkeypatch: Any) -> None:
    """``coolmuscle term URL`` reading a pipe that stays open and silent (module
    docstring of :mod:`coolmuscle.tools.term.terminal`): Ctrl-C (asyncio cancels the
    session) ends the terminal at once.  Its read of standard input waited in asyncio's
    default executor, and closing the loop waits for that executor with no bound: the
    terminal stayed until a line or the end of the input came."""
    read_fd, write_fd = os.pipe()
    stdin = _WatchedInput(os.fdopen(read_fd, "r"))
    monkeypatch.setattr(sys, "stdin", stdin)
    ended = threading.Event()

    async def main() -> None:
        session = asyncio.create_task(term.run_term("coolmuscle://?mode=fast",
                                                    interactive=False))
        assert await wait_until_async(stdin.reading.is_set)
        session.cancel()                       # what asyncio.run does at Ctrl-C
        with contextlib.suppress(asyncio.CancelledError):
            await session

    def run() -> None:
        with asyncio.Runner() as runner:     # its close waits for the default executor
            runner.run(main())
        ended.set()
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        assert ended.wait(3), "the terminal did not end while its input was silent"
    finally:
        os.close(write_fd)                     # the end of the input: the read returns
        thread.join(5)
        stdin.stream.close()
