"""What every transport shares: the host-line port it talks to and the transport contract.

* :class:`Port` is the motor's host line as a transport sees it: ``feed`` delivers
  bytes at the wall-clock instant now (the real-time driver catches the kernel up
  first) and ``add_listener`` subscribes to every byte the motor sends.  ``feed`` is
  the front end's entry point: no exception from the model escapes it
  (docs/architecture.md rule 5).
* :class:`Lane` is one host's input (a TCP client, the pty program, stdin): each
  lane is a host of the line while it is open (``HostLine.open_source``: a host
  alone sees its echo as it types, several see each line's echo whole), its
  bytes are assembled into lines apart (``HostLine.feed(source=lane)``) and
  the lanes take turns, one piece (a whole line, or the unfinished tail) each, so
  no host can starve another by flooding or by leaving a line unfinished.  The
  work done per wake-up of the event loop is bounded (``MAX_PIECES_PER_WAKE``,
  ``MAX_SECONDS_PER_WAKE``); the rest runs at the next wake-up, after the other
  clients' I/O and the motor's own time.  A lane holding more than
  ``LANE_HIGH_WATER`` unrun bytes pauses its reader (back pressure to that host
  only).
* :class:`Transport` is the life cycle (``start``/``describe``/``close``) and the
  ``finished`` event a transport sets when it can no longer serve (stdin closed).
"""

from __future__ import annotations

import asyncio
import logging
import re
import time
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

from ...device.api import Device
from ...device.hostline import HostLine
from ...device.uart import Frame
from ...sim.realtime import RealtimeDriver

log = logging.getLogger(__name__)

#: Default bound of the bytes one client may have queued and unread.  Sized so
#: that many clients fit: 64 clients (the TCP default limit) hold at most 16 MiB.
DEFAULT_MAX_BUFFER = 256 * 1024

#: Pieces (lines) run per wake-up of the event loop before the others get a turn.
MAX_PIECES_PER_WAKE = 64
#: Wall time spent running lines per wake-up (``$`` writes to disk).
MAX_SECONDS_PER_WAKE = 0.02
#: Unrun input bytes a lane may hold before its reader is paused, and resumed.
LANE_HIGH_WATER = 16 * 1024
LANE_LOW_WATER = 4 * 1024
#: With wire pacing (--pace), virtual time of host bytes fed ahead of the wire.
WIRE_AHEAD_NS = 20_000_000

ByteListener = Callable[[bytes], None]

T = TypeVar("T")

LINE_ENDS = (0x0D, 0x0A)
_PIECE = re.compile(rb"[^\r\n]*[\r\n]|[^\r\n]+\Z")


class Port:
    """The host line of one chain, seen from the transports.

    With a ``driver`` every delivery first runs the kernel up to the wall clock,
    and wakes the driver afterwards (the line may have scheduled events).
    ``device`` is the chain behind the line (its ``host_line`` is the port's line),
    for front ends that speak another protocol through the device API (Modbus TCP,
    COM1, EtherCAT, EtherNet/IP, the web page).
    """

    def __init__(self, device: Device, driver: RealtimeDriver | None = None) -> None:
        self.device = device
        self.host_line: HostLine = device.host_line
        self.driver = driver
        self.errors = 0
        self._ready: deque[Lane] = deque()
        self._draining = False
        self._resume_scheduled = False
        self._default: Lane | None = None
        self.wakeups = 0      # drains that stopped at the budget (for tests, reports)

    def call(self, fn: Callable[..., T], *args: Any) -> T:
        """Run ``fn(*args)`` at the wall-clock instant now (caught up), then wake the driver."""
        if self.driver is None:
            return fn(*args)
        return self.driver.call(fn, *args)

    def open_lane(self, name: str = "host") -> Lane:
        """A new host's input, assembled into lines apart from every other host's."""
        return Lane(self, name)

    def feed(self, data: bytes) -> None:
        """Deliver bytes from the default host (its own lane); see :meth:`Lane.feed`."""
        if self._default is None:
            self._default = Lane(self, "default", source=None)
        self._default.feed(data)

    def _enqueue(self, lane: Lane) -> None:
        if lane not in self._ready:
            self._ready.append(lane)
        self._drain()

    def _drain(self) -> None:
        """Run the lanes' pieces in turn, within the per-wake-up budget.

        Each piece is delivered on its own, so a line that makes the model fail
        costs only that line, not the lines after it.
        """
        if self._draining or not self._ready:
            return
        self._draining = True
        try:
            if self.driver is not None:
                self.driver.clock.catch_up()
            try:
                asyncio.get_running_loop()
                paced = True
            except RuntimeError:      # no loop (the port driven directly): run it all now
                paced = False
            deadline = time.perf_counter() + MAX_SECONDS_PER_WAKE
            budget = MAX_PIECES_PER_WAKE
            while self._ready and (budget > 0 or not paced):
                ahead = self._wire_ahead()
                if paced and ahead > WIRE_AHEAD_NS:
                    # --pace: the wire is busy with what was fed; feeding more now would
                    # queue it behind a flood: the lanes take their turns as it frees
                    self._schedule_resume(ahead - WIRE_AHEAD_NS)
                    break
                lane = self._ready.popleft()
                piece = lane._take()
                if piece is None:
                    continue
                if lane.backlog:
                    self._ready.append(lane)
                budget -= 1
                try:
                    self.host_line.feed(piece, lane.source)
                except Exception:
                    self.errors += 1
                    log.exception("motor model failed on host input %r", piece[:64])
                if lane.closing and not lane.backlog:
                    lane._end()
                if paced and time.perf_counter() > deadline:
                    break
            if self._ready and not self._resume_scheduled:
                self.wakeups += 1
                self._schedule_resume()
        finally:
            self._draining = False
        if self.driver is not None:
            self.driver.wake()

    def _wire_ahead(self) -> int:
        return self.host_line.rx_backlog_ns()

    def _schedule_resume(self, after_ns: int = 0) -> None:
        if self._resume_scheduled:
            return
        loop = asyncio.get_running_loop()     # only paced drains stop at the budget
        self._resume_scheduled = True

        def resume() -> None:
            self._resume_scheduled = False
            self._drain()
        if after_ns <= 0:
            loop.call_soon(resume)
            return
        scale = (self.driver.clock.scale if self.driver is not None else 1.0) or 1.0
        loop.call_later(after_ns / 1e9 / scale, resume)

    def _open_source(self, source: object) -> None:
        """A host joined the line: the host line sends whole-line echoes while it is
        not alone (``HostLine.open_source``)."""
        self.host_line.open_source(source)

    def _close_lane(self, lane: Lane) -> None:
        if lane in self._ready:
            self._ready.remove(lane)
        try:
            if lane.source is not None:
                self.host_line.end_source(lane.source)
        except Exception:
            log.exception("host line failed to end a host's lane")

    def add_listener(self, listener: ByteListener,
                     lane: Lane | None = None) -> Callable[[], None]:
        """Receive every byte the motor sends; returns an unsubscribe function.

        ``lane``: the host this listener reads for (its port's rate, :meth:`set_host_baud`)."""
        if lane is None:
            return self.host_line.add_listener(listener)
        return self.host_line.add_listener(listener, lane.source)

    def set_host_baud(self, lane: Lane, baud: Callable[[], int | None]) -> None:
        """How to read the baud rate ``lane``'s host set on its port (the pty: the
        client's termios speed); with wire pacing the host line garbles the bytes both
        ways while it differs from K20 (``HostLine.set_host_baud``)."""
        setter = getattr(self.host_line, "set_host_baud", None)
        if setter is not None:
            setter(lane.source, baud)

    def set_host_frame(self, lane: Lane, frame: Callable[[], Frame | None]) -> None:
        """How to read the frame ``lane``'s host set on its port (data bits, parity,
        stop bits: an RFC 2217 client's); with wire pacing it is read beside the rate
        (``HostLine.set_host_frame``)."""
        setter = getattr(self.host_line, "set_host_frame", None)
        if setter is not None:
            setter(lane.source, frame)

    def discard_partial(self) -> bool:
        """Forget a partly received line of the default host (see report)."""
        try:
            self.host_line.discard_partial()
        except Exception:
            log.exception("host line failed to discard a partial line")
            return False
        return True


class Lane:
    """One host's input on the shared host line (see the module docstring).

    ``feed`` queues the host's bytes split after each line end; the port runs
    them whole, in turn with the other lanes.  ``set_flow(pause, resume)``
    installs the reader's back pressure; ``close`` ends the host (its half line
    is forgotten, a bank upload it opened ends).
    """

    def __init__(self, port: Port, name: str, *, source: object = ...) -> None:
        self.port = port
        self.name = name
        self.source: object = self if source is ... else source
        self._pieces: deque[bytes] = deque()
        self.backlog = 0
        self.closed = False
        self.closing = False
        self._paused = False
        self._pause: Callable[[], None] | None = None
        self._resume: Callable[[], None] | None = None
        port._open_source(self.source)

    def set_flow(self, pause: Callable[[], None], resume: Callable[[], None]) -> None:
        """Reader controls: called when the backlog passes the high / low water mark."""
        self._pause, self._resume = pause, resume

    def feed(self, data: bytes) -> None:
        """Queue bytes from this host; they run in turn (failures logged, never raised)."""
        if not data or self.closed or self.closing:
            return
        pieces = split_after_line_ends(data)
        self._pieces.extend(pieces)
        self.backlog += len(data)
        if self.backlog > LANE_HIGH_WATER and not self._paused and self._pause is not None:
            self._paused = True
            self._call(self._pause)
        self.port._enqueue(self)

    def _take(self) -> bytes | None:
        if not self._pieces:
            return None
        piece = self._pieces.popleft()
        mode = self.port.host_line.mode
        if mode is not None and mode.active():
            # COM0 speaks Modbus RTU (5.6): no lines; a frame's bytes go in together
            piece = b"".join((piece, *self._pieces))
            self._pieces.clear()
        elif ends_mid_line(piece):     # an unfinished tail: join what follows it so far
            while self._pieces and ends_mid_line(piece):
                piece += self._pieces.popleft()
        self.backlog -= len(piece)
        if self._paused and self.backlog <= LANE_LOW_WATER:
            self._paused = False
            if self._resume is not None:
                self._call(self._resume)
        return piece

    @staticmethod
    def _call(fn: Callable[[], None]) -> None:
        try:
            fn()
        except Exception:
            log.exception("lane flow control failed")

    def purge(self) -> None:
        """Forget the bytes of this host not yet on the line (a port's transmit buffer
        emptied)."""
        self._pieces.clear()
        self.backlog = 0
        if self._paused:
            self._paused = False
            if self._resume is not None:
                self._call(self._resume)

    def close(self) -> None:
        """The host went away: the lines it sent still run, in turn; then its half
        line is forgotten and what it owned (a bank upload) ends."""
        if self.closed or self.closing:
            return
        self.closing = True
        if not self.backlog:
            self._end()

    def _end(self) -> None:
        if self.closed:
            return
        self.closed = True
        self._pieces.clear()
        self.backlog = 0
        self.port._close_lane(self)


def split_after_line_ends(data: bytes) -> list[bytes]:
    """Split ``data`` after every CR and LF (the last piece may have no line end)."""
    return _PIECE.findall(data)


def ends_mid_line(data: bytes) -> bool:
    """True when ``data`` leaves a line unfinished (its last byte is no CR/LF)."""
    return bool(data) and data[-1] not in LINE_ENDS


async def close_stream_server(server: asyncio.AbstractServer | None,
                              writers: Iterable[asyncio.StreamWriter]) -> None:
    """Stop accepting, drop every connection at once, then wait for the server to close
    (the TCP line, Modbus TCP and EtherNet/IP servers end the same way)."""
    if server is not None:
        server.close()
    for writer in list(writers):
        writer.transport.abort()
    if server is not None:
        await server.wait_closed()


class Transport(ABC):
    """A byte pipe between host programs and a :class:`Port`, run in an asyncio loop."""

    #: Registry name (``tcp``, ``pty``, ``stdio``).
    name: str = ""

    #: When ``finished`` is set, the whole simulator should stop (stdin closed).
    stops_service: bool = False

    def __init__(self) -> None:
        self.finished = asyncio.Event()
        self.port: Port | None = None

    @abstractmethod
    async def start(self, port: Port) -> None:
        """Open the pipe and start moving bytes; raise ``TransportError`` if it cannot."""

    @abstractmethod
    def describe(self) -> str:
        """One banner item, e.g. ``tcp: 127.0.0.1:5150``."""

    @abstractmethod
    async def close(self) -> None:
        """Stop moving bytes and release every resource (idempotent)."""

    def info(self) -> dict[str, Any]:
        """Machine-readable address details (``{"host": ..., "port": ...}``)."""
        return {}

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.describe()}>"
