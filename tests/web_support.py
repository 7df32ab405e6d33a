"""Shared helpers of the web dashboard tests: a served chain, a TCP host line, a WS client.

The chain runs in a :class:`ServiceThread` with the TCP transport (the motor's own host
line, an independent door to check what the page did) and the web transport.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import socket
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.transports import create
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.tools.web.server import WebTransport

ROOT = Path(__file__).resolve().parents[1]

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]


def require_browser() -> ModuleType:
    """``playwright.sync_api`` with Debian's Chromium, or the calling test module is
    skipped where they are missing (an error in CI: scripts/test installs them)."""
    api = pytest.importorskip("playwright.sync_api")
    if not os.path.exists(CHROMIUM):
        if os.environ.get("CI"):
            raise RuntimeError(f"{CHROMIUM} is missing: scripts/test installs Debian's chromium")
        pytest.skip(f"{CHROMIUM} not installed (apt-get install chromium)",
                    allow_module_level=True)
    return api


def chromium(api: ModuleType) -> Iterator[Any]:
    """A headless Debian Chromium from ``api`` (:func:`require_browser`), closed after:
    the body of each browser test module's ``browser`` fixture."""
    with api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


def output_dir() -> Path:
    """Where the browser tests write screenshots (``$COOLMUSCLE_TEST_OUTPUT`` or out/test-web)."""
    path = Path(os.environ.get("COOLMUSCLE_TEST_OUTPUT", ROOT / "out" / "test-web"))
    path.mkdir(parents=True, exist_ok=True)
    return path


def serve(motors: int = 1, **web: Any) -> ServiceThread:
    """A started chain with ``tcp`` (transports[0]) and ``web`` (transports[1]) on free ports."""
    return ServiceThread(lambda: Chain(motors=motors),
                         lambda: [create("tcp", port=0), WebTransport(port=0, **web)]).start()


class HostLine:
    """A TCP client of the motor's own host line (6.6 queries, reply lines)."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        self.buf = b""

    def query(self, line: str, answer: str, timeout: float = 5.0) -> str:
        """Send ``line`` and return the first received line matching regex ``answer``."""
        self.sock.sendall(line.encode() + b"\r")
        return self.wait_for(answer, timeout)

    def wait_for(self, answer: str, timeout: float = 5.0) -> str:
        deadline = time.monotonic() + timeout
        pattern = re.compile(answer)
        while True:
            while b"\n" in self.buf or b"\r" in self.buf:
                line, self.buf = re.split(rb"\r\n|\r|\n", self.buf, maxsplit=1)
                text = line.decode("latin-1")
                if pattern.fullmatch(text):
                    return text
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"no line matching {answer!r} on the host line")
            self.sock.settimeout(left)
            chunk = self.sock.recv(4096)
            if not chunk:
                raise AssertionError("host line closed")
            self.buf += chunk

    def lines_within(self, seconds: float) -> list[str]:
        """Every line received from now for ``seconds`` (a fixed window: for silence)."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            self.sock.settimeout(left)
            try:
                chunk = self.sock.recv(4096)
            except TimeoutError:
                break
            if not chunk:
                raise AssertionError("host line closed")
            self.buf += chunk
        *lines, self.buf = re.split(rb"\r\n|\r|\n", self.buf)
        return [line.decode("latin-1") for line in lines if line]

    def close(self) -> None:
        self.sock.close()


_PENDING: dict[int, list[dict[str, Any]]] = {}


async def ws_frames(ws: Any, keep: Callable[[dict[str, Any]], bool], timeout: float = 5.0
                    ) -> dict[str, Any]:
    """The first JSON frame from ``ws`` for which ``keep`` is true (a message holds one
    frame a line)."""
    pending = _PENDING.setdefault(id(ws), [])

    async def wait() -> dict[str, Any]:
        while True:
            while pending:
                frame = pending.pop(0)
                if keep(frame):
                    return frame
            msg = await ws.receive()
            if msg.type.name != "TEXT":
                raise AssertionError(f"socket ended: {msg.type.name} {msg.data!r}")
            pending.extend(json.loads(line) for line in msg.data.split("\n"))
    return await asyncio.wait_for(wait(), timeout)


async def ask(ws: Any, request: dict[str, Any], rid: int = 1, timeout: float = 5.0
              ) -> dict[str, Any]:
    """Send a request and return its ``result``."""
    await ws.send_str(json.dumps({**request, "id": rid}))
    return await ws_frames(ws, lambda f: f.get("t") == "result" and f.get("id") == rid, timeout)


def count_snapshots(url: str, pages: int, seconds: float, out: Any) -> None:
    """Child process (as browsers are): ``pages`` WebSocket clients watch ``url`` for
    ``seconds``; puts each one's count of ``snap`` frames (and the motors in them)."""
    import aiohttp

    async def page(session: Any) -> tuple[int, int]:
        async with session.ws_connect(url + "ws", max_msg_size=0) as ws:
            await ws_frames(ws, lambda f: f["t"] == "hello", timeout=10)
            count, motors, end = 0, 0, time.monotonic() + seconds
            while time.monotonic() < end:
                frame = await ws_frames(ws, lambda f: f["t"] == "snap", timeout=5)
                count, motors = count + 1, len(frame["m"])
            return count, motors

    async def main() -> list[tuple[int, int]]:
        async with aiohttp.ClientSession() as session:
            return list(await asyncio.gather(*(page(session) for _ in range(pages))))
    out.put(asyncio.run(main()))
