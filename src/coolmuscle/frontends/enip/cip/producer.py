"""The T->O producer: a thread that sends Class 1 packets on time (CIP Vol 1 3-4.4).

The asyncio loop wakes with millisecond granularity (epoll), too coarse for an RPI
of 2 ms, so productions are timed by this thread (``Event.wait`` sleeps with the
kernel's high-resolution timers).  It never touches the model (docs/architecture.md
rule 2): it sends the input image the connection table holds and asks the loop,
through ``call_soon_threadsafe``, to refresh that image for the next packet.  The
table is shared under one lock with the loop thread, which does no model work under it.

The thread needs the GIL for every packet: while it runs, the interpreter's switch
interval is cut to :data:`SWITCH_INTERVAL`, so a busy model thread gives the GIL up
within that time instead of the default 5 ms (2.5 RPIs of 2 ms).
"""

from __future__ import annotations

import logging
import os
import socket
import sys
import threading
import time
from collections.abc import Callable

from .io import ConnectionTable

log = logging.getLogger(__name__)

IDLE_WAIT = 0.1        # seconds between looks at the table when nothing is due
SWITCH_INTERVAL = 0.0002   # s: how long the producer waits at most for the GIL


class Producer(threading.Thread):
    """Send every T->O packet of ``table`` when it is due, through ``sock``."""

    def __init__(self, table: ConnectionTable, sock: socket.socket, lock: threading.Lock,
                 refresh: Callable[[], None], priority: int | None = None) -> None:
        super().__init__(name="enip-producer", daemon=True)
        self.table = table
        self.sock = sock
        self.lock = lock
        self.refresh = refresh
        self._wake = threading.Event()
        self._stopping = False
        self.sent = 0
        self.send_errors = 0
        self.priority = priority
        self.priority_error: str | None = None
        self._old_switch = sys.getswitchinterval()

    def start(self) -> None:
        sys.setswitchinterval(min(self._old_switch, SWITCH_INTERVAL))
        super().start()

    def wake(self) -> None:
        """Re-plan now (a connection was opened or closed)."""
        self._wake.set()

    def stop(self) -> None:
        self._stopping = True
        self._wake.set()
        if self.is_alive():
            self.join(2.0)
        sys.setswitchinterval(self._old_switch)

    def _set_priority(self) -> None:
        """SCHED_FIFO for this thread only (Linux: pid 0 is the calling thread)."""
        if self.priority is None:
            return
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.priority))
        except (OSError, AttributeError, ValueError) as exc:
            self.priority_error = str(exc)
            log.warning("enip: real-time priority %s refused: %s", self.priority, exc)

    def run(self) -> None:
        self._set_priority()
        while not self._stopping:
            with self.lock:
                nxt = self.table.next_production()
            delay = IDLE_WAIT if nxt is None else (nxt - time.monotonic_ns()) / 1e9
            if delay > 0:
                self._wake.wait(min(delay, IDLE_WAIT))
                self._wake.clear()
                continue
            with self.lock:
                lost = self.table.lost
                packets = self.table.due(time.monotonic_ns())
                produced = bool(packets) or self.table.lost != lost   # sent or lost
            for packet, addr in packets:
                self._send(packet, addr)
            if produced:
                self.refresh()

    def _send(self, packet: bytes, addr: tuple[str, int]) -> None:
        try:
            self.sock.sendto(packet, addr)
            self.sent += 1
        except OSError as exc:            # a full buffer or no route: this packet is lost
            self.send_errors += 1
            log.debug("enip: T->O to %s failed: %s", addr, exc)
