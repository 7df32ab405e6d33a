"""CML over the mailbox: F581h-F584h out, F591h-F594h back
(ethercat-bridge-users-guide.txt 7.2, Appendix 2).

The master writes a CML string of at most 64 bytes (the table's ``max_len`` makes a
longer one abort 06070012h "length of service parameter too high"); the bridge adds
CR LF and sends it over the CM port (:class:`~.link.CmLink`).  When its last byte
has arrived the motor runs it as the line of origin ``fieldbus`` through the device
API.  Every line the motor prints on that port (the replies to those strings, and
its own reports: ``Ux``, ``IN``/``OUT``, ``Origin``, error messages, bank output)
crosses the line back and, from the first bridge cycle after it arrived, is one
F59xh read.  An empty queue reads "Null\\r\\n" (7.2.2 CML Receive 2).  Lines queue in
order; a line longer than the 64-byte object is read in 64-byte pieces.

Threads: :meth:`submit` and :meth:`read` run in the frame thread (deque appends
and pops only); :meth:`pump` and the event listener run in the model thread.
"""

from __future__ import annotations

import logging
from collections import deque
from functools import partial
from typing import Final

from ....device import Device, Event
from ....sim.kernel import PRIO_IO
from .link import CmLink

log = logging.getLogger(__name__)

NULL: Final = "Null\r\n"
MAX_STRING: Final = 64                         # 7.2.2 "Max String Size 64bytes"
#: Lines the motor prints on its port (origin ``fieldbus`` is the bridge's own).
PORT_ORIGINS: Final = frozenset({"fieldbus", "motor", "bank", "ladder"})
#: Lines kept for a master that does not poll (older ones are dropped and counted).
QUEUE_LIMIT: Final = 4096


class CmlMailbox:
    """The CML strings of one axis, both ways."""

    def __init__(self, axis: int, link: CmLink) -> None:
        self.axis = axis
        self.link = link
        self._outbox: deque[str] = deque()
        self._arriving: deque[tuple[int, str]] = deque()
        self._visible: deque[str] = deque()
        self.dropped = 0
        self.sent: list[str] = []            # what went to the motor, for tests and traces

    # -- frame thread ------------------------------------------------------------
    def submit(self, text: str) -> None:
        """F58xh written: queue the string (without a CR LF the master should not add)."""
        self._outbox.append(text.rstrip("\r\n").split("\r")[0].split("\n")[0])

    def read(self) -> str:
        """F59xh read: the oldest line not read yet, or "Null\\r\\n"."""
        try:
            return self._visible.popleft()
        except IndexError:
            return NULL

    # -- model thread --------------------------------------------------------------
    def pump(self, device: Device, now: int) -> None:
        """One bridge cycle: send what the master wrote, publish what has arrived."""
        while self._outbox:
            text = self._outbox.popleft()
            at = self.link.send(len(text) + 2, now)
            device.kernel.schedule_at(at, partial(self._deliver, device, text),
                                      priority=PRIO_IO, name=f"ethercat-cml-{self.axis}")
        while self._arriving and self._arriving[0][0] <= now:
            self._publish(self._arriving.popleft()[1])

    def _deliver(self, device: Device, text: str) -> None:
        self.sent.append(text)
        if not text:
            return
        try:
            device.execute(text, origin="fieldbus", motor=self.axis)
        except Exception:              # the device answers bad CML itself; this is a bug
            log.exception("CML string %r for ID%d failed", text, self.axis)

    def on_event(self, event: Event) -> None:
        """A line of the motor: it crosses the CM port back to the bridge."""
        if event.motor != self.axis or event.origin not in PORT_ORIGINS:
            return
        line = event.text + "\r\n"
        self._arriving.append((self.link.receive(len(line), event.time), line))

    def _publish(self, line: str) -> None:
        for start in range(0, len(line), MAX_STRING):
            if len(self._visible) >= QUEUE_LIMIT:
                self._visible.popleft()
                self.dropped += 1
            self._visible.append(line[start:start + MAX_STRING])

    def clear(self) -> None:
        """Forget what is queued (a bridge restart)."""
        self._outbox.clear()
        self._arriving.clear()
        self._visible.clear()
