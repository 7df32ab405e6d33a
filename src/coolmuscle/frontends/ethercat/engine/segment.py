"""A segment: several ESCs in a line, as a master's frames meet them (ETG.1000.4 3.2).

Each ESC has port 0 (towards the master) and port 1 (towards the next slave).  A frame
enters the first ESC at port 0, passes its processing unit, leaves by port 1 into the
next ESC's port 0, and so on; the last ESC, whose port 1 has no link, closes the loop
and the frame travels back through the ring, unchanged, to the master.  So the slaves
process a frame in line order: an auto-increment address (APRD, APWR, APRW, ARMW) is
counted up by each ESC it passes and read or written by the one where it is 0,
broadcasts reach every ESC, a logical datagram is served by the FMMUs of every slave
it overlaps, and the working counters add up along the way (:meth:`.esc.Esc.handle`).

A cable can be pulled (:meth:`Segment.unplug`, the link into an ESC's port 0 down) and
put back (:meth:`Segment.plug`): the ESC in front of it loses the link of its port 1 and
closes its loop there (DL status 0x0110 shows it), so the frames come back from it and
everything behind the cable is gone from the segment (a real line has no bypass).  The
ESCs behind it still run: their watchdogs expire without frames (:meth:`Segment.tick`
ticks every ESC).  A master that closes the loop of a port 1 itself (DL control 0x0101)
ends the line there too.

Where a frame passes a port is one place, :meth:`Segment.process`, with one hook,
:attr:`Segment.tap`: called as the frame arrives at each ESC's port 0 and once as it
leaves the first ESC towards the master (``RETURNED``), it may hand back the frame
(the same, or altered) or ``None`` (the frame is lost there).  Faults on the wire
(lost frames, a working counter off by one, a lost mailbox answer) hook in there.

No socket, no clock, no thread: a cable changed from another thread takes effect at
the next :meth:`Segment.process` or :meth:`Segment.tick`, in the frame thread.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

from .esc import Esc, is_ethercat

#: The ``position`` a tap is called with when the frame goes back to the master.
RETURNED = -1

#: A frame at a port: ``(position, frame)`` -> the frame that goes on, or None (lost).
Tap = Callable[[int, bytearray], bytearray | None]


class Segment:
    """ESCs ``escs`` in line order (position 0 next to the master)."""

    def __init__(self, escs: Sequence[Esc]) -> None:
        if not escs:
            raise ValueError("a segment has at least one slave")
        self.escs = tuple(escs)
        #: The cable into each ESC's port 0 is plugged (what the frame thread applied).
        self._plugged = (True,) * len(self.escs)
        self._wanted = self._plugged
        self._cables = threading.Lock()
        self.tap: Tap | None = None
        #: Frames processed, and how many ESCs the last one passed.
        self.frames = 0
        self.reached = 0
        self._apply_links()

    # -- cables ---------------------------------------------------------------------
    @property
    def plugged(self) -> tuple[bool, ...]:
        """Whether the cable into each ESC's port 0 is plugged (as last asked)."""
        return self._wanted

    def unplug(self, position: int) -> None:
        """Pull the cable into the port 0 of the ESC at ``position`` (0-based)."""
        self._set(position, False)

    def plug(self, position: int) -> None:
        """Put the cable into the port 0 of the ESC at ``position`` back."""
        self._set(position, True)

    def _set(self, position: int, up: bool) -> None:
        if not 0 <= position < len(self.escs):
            raise IndexError(f"no slave at position {position} (0..{len(self.escs) - 1})")
        with self._cables:                 # two threads may pull two cables at once
            wanted = list(self._wanted)
            wanted[position] = up
            self._wanted = tuple(wanted)   # readers see the old tuple or the new one

    def _apply_links(self) -> None:
        """DL status of every ESC from the cables: port 0 has a link when its own cable
        is plugged, port 1 when the next ESC's is."""
        plugged = self._plugged = self._wanted
        last = len(self.escs) - 1
        for n, esc in enumerate(self.escs):
            esc.set_links(plugged[n], n < last and plugged[n + 1])

    def visible(self) -> int:
        """ESCs a frame reaches now: up to the first pulled cable or closed loop."""
        count = 0
        for n, esc in enumerate(self.escs):
            if not self._wanted[n]:
                break
            count += 1
            if n == len(self.escs) - 1 or not self._wanted[n + 1] or not esc.forwards:
                break
        return count

    # -- frames -------------------------------------------------------------------------
    def process(self, frame: bytes | bytearray | memoryview, now: int = 0
                ) -> bytearray | None:
        """One frame from the master through the line and back at time ``now`` (ns):
        the frame the master receives, or None (not EtherCAT, or lost on the way)."""
        if self._wanted is not self._plugged:
            self._apply_links()
        if not is_ethercat(frame) or not self._plugged[0]:
            self.tick(now)
            return None
        out = self._through(bytearray(frame), now)
        self.frames += 1
        self.tick(now)
        return out

    def _through(self, buf: bytearray, now: int) -> bytearray | None:
        """The frame's way: each ESC's port 0 in turn (the tap first, then its processing
        unit) up to the one whose port 1 is closed, then back to the master."""
        tap, plugged, escs = self.tap, self._plugged, self.escs
        last = len(escs) - 1
        self.reached = 0
        for position, esc in enumerate(escs):
            if tap is not None:
                arrived = tap(position, buf)
                if arrived is None:
                    return None
                buf = arrived
            esc.handle(buf, now)
            self.reached = position + 1
            if position == last or not plugged[position + 1] or not esc.forwards:
                break                  # port 1 closed: the frame turns back here
        return tap(RETURNED, buf) if tap is not None else buf

    def tick(self, now: int) -> None:
        """Run every ESC's watchdog at ``now`` (ns), reached by frames or not."""
        if self._wanted is not self._plugged:
            self._apply_links()
        for esc in self.escs:
            esc.tick(now)
