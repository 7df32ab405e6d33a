"""What every transport shares: the host-line port it talks to and the transport contract.

* :class:`Port` is the motor's host line as a transport sees it: ``feed`` delivers
  bytes at the wall-clock instant now (the real-time driver catches the kernel up
  first) and ``add_listener`` subscribes to every byte the motor sends.  ``feed`` is
  the front end's entry point: no exception from the model escapes it
  (docs/architecture.md rule 5).
* :class:`Transport` is the life cycle (``start``/``describe``/``close``) and the
  ``finished`` event a transport sets when it can no longer serve (stdin closed).
"""

from __future__ import annotations

import asyncio
import logging
import re
from abc import ABC, abstractmethod
from typing import Any, Callable

from ...device.hostline import HostLine
from ...sim.realtime import RealtimeDriver

log = logging.getLogger(__name__)

#: Default bound of the bytes one client may have queued and unsent.
DEFAULT_MAX_BUFFER = 1 << 20

ByteListener = Callable[[bytes], None]

LINE_ENDS = (0x0D, 0x0A)
_PIECE = re.compile(rb"[^\r\n]*[\r\n]|[^\r\n]+\Z")


class Port:
    """The host line of one chain, seen from the transports.

    With a ``driver`` every delivery first runs the kernel up to the wall clock,
    and wakes the driver afterwards (the line may have scheduled events).
    ``device`` is the chain behind the line, for front ends that speak another
    protocol through the device API (Modbus TCP, COM1).
    """

    def __init__(self, host_line: HostLine, driver: RealtimeDriver | None = None,
                 device: Any = None) -> None:
        self.host_line = host_line
        self.driver = driver
        self.device = device
        self.errors = 0

    def call(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Run ``fn(*args)`` at the wall-clock instant now (caught up), then wake the driver."""
        if self.driver is None:
            return fn(*args)
        return self.driver.call(fn, *args)

    def feed(self, data: bytes) -> None:
        """Deliver bytes from a host; model failures are logged, never raised.

        The bytes are delivered line by line, so a line that makes the model fail
        costs only that line, not the lines after it in the same chunk.
        """
        if not data:
            return
        if self.driver is not None:
            self.driver.clock.catch_up()
        for piece in split_after_line_ends(data):
            try:
                self.host_line.feed(piece)
            except Exception:
                self.errors += 1
                log.exception("motor model failed on host input %r", piece[:64])
        if self.driver is not None:
            self.driver.wake()

    def add_listener(self, listener: ByteListener) -> Callable[[], None]:
        """Receive every byte the motor sends; returns an unsubscribe function."""
        return self.host_line.add_listener(listener)

    def discard_partial(self) -> bool:
        """Forget a partly received line, if the host line supports it (see report)."""
        discard = getattr(self.host_line, "discard_partial", None)
        if discard is None:
            return False
        try:
            discard()
        except Exception:
            log.exception("host line failed to discard a partial line")
            return False
        return True


def split_after_line_ends(data: bytes) -> list[bytes]:
    """Split ``data`` after every CR and LF (the last piece may have no line end)."""
    return _PIECE.findall(data)


def ends_mid_line(data: bytes) -> bool:
    """True when ``data`` leaves a line unfinished (its last byte is no CR/LF)."""
    return bool(data) and data[-1] not in LINE_ENDS


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
