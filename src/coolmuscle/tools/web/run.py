"""``--web`` on the command line: the option's value and a script played for the page.

* :func:`web_transport` builds the :class:`~.server.WebTransport` for ``[HOST:]PORT``
  (``coolmuscle sim --web``);
* :func:`run_script_web` is ``coolmuscle run script.cml --web``: the script is played in
  real time (each ``@wait`` takes its seconds on the wall clock, docs/scripts.md) on a
  chain served to the dashboard, so a person watches the run; it starts when the
  first page connects and the page stays live after the script until Ctrl-C.
  Expectation lines (``<<``) are not checked here: ``coolmuscle run`` without
  ``--web`` checks them in fast virtual time, byte for byte.
"""

from __future__ import annotations

import asyncio
import logging
import re
import sys
from collections.abc import Callable
from typing import TextIO

from ...device import Device
from ...frontends.transports.base import Port
from ...frontends.transports.service import Service
from ...sim.kernel import Kernel, seconds
from ..cli.stopsignals import ignore_stop_signals, run_served
from ..script.runner import Script, Step, TranscriptEntry
from .access import parse_web_address
from .server import WebTransport

log = logging.getLogger(__name__)


def web_transport(address: str, *, title: str = "", record: bool = False) -> WebTransport:
    """The dashboard transport for ``[HOST:]PORT`` (``TransportError`` when malformed)."""
    host, port = parse_web_address(address)
    return WebTransport(host=host, port=port, title=title, record=record)


class _Lines:
    """Host-line bytes cut into lines, printed with their virtual time as they come."""

    def __init__(self, kernel: Kernel, show: Callable[[TranscriptEntry], None]) -> None:
        self.kernel = kernel
        self.show = show
        self.lines: list[str] = []
        self._buf = bytearray()

    def on_bytes(self, data: bytes) -> None:
        for byte in data:
            if byte in (0x0D, 0x0A):
                if self._buf:
                    self.lines.append(self._buf.decode("latin-1"))
                    self.show(TranscriptEntry(self.kernel.now, "<", bytes(self._buf)))
                    self._buf.clear()
            else:
                self._buf.append(byte)


async def play(script: Script, service: Service,
               show: Callable[[TranscriptEntry], None]) -> str | None:
    """Play ``script`` on ``service`` in real time; returns why it stopped early, or None."""
    chain, port = service.chain, service.port
    lines = _Lines(chain.kernel, show)
    remove = port.add_listener(lines.on_bytes)
    scale = service.driver.clock.scale
    try:
        for step in script.steps:
            stopped = await _step(step, chain, port, lines, show, scale)
            if stopped:
                return stopped
    finally:
        remove()
    return None


async def _step(step: Step, chain: Device, port: Port, lines: _Lines,
                show: Callable[[TranscriptEntry], None], scale: float) -> str | None:
    if step.kind in ("send", "raw"):
        port.call(_now)                   # the kernel caught up: the line's own instant
        show(TranscriptEntry(chain.kernel.now, ">", step.data, step.line_no))
        port.feed(step.data)
    elif step.kind == "wait":
        await asyncio.sleep(step.seconds / scale)
    elif step.kind == "input":
        port.call(chain.set_input, step.args[0], step.args[1], bool(step.args[2]))
    elif step.kind == "analog":
        port.call(chain.set_analog, step.args[0], step.args[1])
    elif step.kind == "until":
        assert step.pattern is not None
        if not await _until(step.pattern, lines, step.seconds / scale):
            return f"line {step.line_no}: @until {step.pattern.pattern!r} timed out " \
                   f"after {step.seconds:g} s"
    return None


def _now() -> None:
    """Nothing: :meth:`Port.call` catches the kernel up to the wall clock first."""


async def _until(pattern: re.Pattern[str], lines: _Lines, timeout: float) -> bool:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    seen = len(lines.lines)
    while True:
        while seen < len(lines.lines):
            seen += 1
            if pattern.search(lines.lines[seen - 1]):
                return True
        if loop.time() >= deadline:
            return False
        await asyncio.sleep(0.01)


def run_script_web(script: Script, chain: Device, address: str, *, until: float | None = None,
                   title: str = "", out: TextIO | None = None,
                   err: Callable[[str], None] | None = None) -> None:
    """``coolmuscle run FILE --web``: serve the dashboard, play the script in real time."""
    out = out or sys.stdout
    say = err or (lambda text: print(text, file=sys.stderr, flush=True))

    def show(entry: TranscriptEntry) -> None:
        out.write(entry.format() + "\n")
        out.flush()

    web = web_transport(address, title=title, record=True)
    run_served(lambda stop: _serve_run(script, chain, web, until, show, say, stop))


async def _serve_run(script: Script, chain: Device, web: WebTransport, until: float | None,
                     show: Callable[[TranscriptEntry], None], say: Callable[[str], None],
                     stop: asyncio.Event) -> None:
    service = Service(chain, [web])
    await service.start()
    try:
        say(f"coolmuscle: {web.describe()}   (the script starts when a page connects)")
        while not web.hub or not web.hub.clients:
            if stop.is_set():
                return
            await asyncio.sleep(0.05)
        played = asyncio.ensure_future(play(script, service, show))
        if not await _done_before_stop(played, stop):
            return                     # stopped while the script played: no more of it
        why = played.result()
        if why is None and until is not None:
            rest = seconds(until) - chain.kernel.now
            if rest > 0:
                await _sleep_or_stop(rest / 1e9 / service.driver.clock.scale, stop)
        say(f"coolmuscle: {why or 'script done'}; the page stays live until Ctrl-C")
        await stop.wait()
    finally:
        ignore_stop_signals()          # a second signal must not cut the clean-up short
        await service.close()


async def _done_before_stop(work: asyncio.Future[str | None], stop: asyncio.Event) -> bool:
    """Wait for ``work`` or ``stop``, whichever comes first; on ``stop`` ``work`` is
    cancelled (a script in an ``@wait`` or ``@until`` of many seconds must not hold a
    stop signal until it ends) and ``False`` is returned."""
    stopping = asyncio.ensure_future(stop.wait())
    try:
        await asyncio.wait((work, stopping), return_when=asyncio.FIRST_COMPLETED)
    finally:
        stopping.cancel()
        if not work.done():
            work.cancel()
            await asyncio.gather(work, return_exceptions=True)
    return not work.cancelled()


async def _sleep_or_stop(delay: float, stop: asyncio.Event) -> None:
    try:
        async with asyncio.timeout(delay):
            await stop.wait()
    except TimeoutError:
        pass
