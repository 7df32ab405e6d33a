"""The ``ethercat`` door's wire faults on a segment of bridges (docs/wire-faults.md).

The fault state is the device's (``Device.wire_faults``, in virtual time: a fault is
live from ``at`` to ``until`` by kernel events).  The frames come in the frame thread
(:class:`~..transport.FrameThread`), not the model's, and a frame is answered at once
(as an ESC does, in hardware): it cannot wait for the model.  So the two threads meet
under one lock, in two directions:

* the model's thread publishes the per-frame faults live now, at the virtual instant a
  fault enters or leaves its window (``WireFaults.watch(..., every_kind=True)``), and
  installs the segment's tap only while one is live: without a fault the frames pass
  no hook at all;
* the frame thread decides for each frame with each fault's own generator
  (:meth:`~coolmuscle.device.wire.schedule.ActiveFault.decide`: only this door's
  faults, only in this thread), does it, and leaves what it did in a list that the next
  bridge cycle's :meth:`~EthercatFaults.sync` records in the model's thread (an event of
  kind ``wire``, the trace, the transcript; its time is that cycle's instant) and where
  it ends a fault whose ``count`` is spent.

So two runs that present the same frames in the same order to the same live faults
make the same choices, bit for bit; the sans-IO tests drive both threads' parts in
turn.  The kinds, where they act (:class:`~..engine.segment.Segment`'s tap is called as
a frame arrives at each ESC's port 0 and as it leaves for the master):

* ``lost_frame``: ``way = "out"`` at the named bridge's port 0 (it and the bridges
  behind it never see the frame); ``way = "back"`` as it leaves for the master (every
  bridge has processed it);
* ``wkc``: as the frame leaves, the working counter (its last two bytes) of its first
  logical datagram (or first datagram) changes by ``delta``;
* ``mailbox_lost``: a frame that emptied a bridge's full read mailbox (SM1: the master
  read the answer) is lost on its way back; the answer is gone from the ESC, so the
  master must ask for it again with SM1's repeat request (ETG.1000.4 mailbox repeat,
  :meth:`~..engine.esc.Esc._repeat`);
* ``link_down`` (lasting): the model's thread pulls the cable into the bridge's port 0
  (:meth:`~..engine.segment.Segment.unplug`) and puts it back at ``until``; the SM
  watchdogs do the rest (SAFE-OP + 001Bh);
* ``late_cycle``: in the model's thread, a bridge cycle starts ``ms`` late and the cycles
  due meanwhile are skipped (:meth:`EthercatFaults.late_cycle`).
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

from ....device.wire import ActiveFault, WireFaults
from ....sim.kernel import NS_PER_MS
from ..engine import esc as E
from ..engine.segment import RETURNED, Segment

__all__ = ["EthercatFaults", "DOOR"]

DOOR = "ethercat"
#: The kinds decided per frame, in the frame thread.
FRAME_KINDS = frozenset({"lost_frame", "wkc", "mailbox_lost"})
_LOGICAL = frozenset({E.LRD, E.LWR, E.LRW})
_NAMES = {E.LRD: "LRD", E.LWR: "LWR", E.LRW: "LRW", E.APRD: "APRD", E.APWR: "APWR",
          E.APRW: "APRW", E.FPRD: "FPRD", E.FPWR: "FPWR", E.FPRW: "FPRW", E.BRD: "BRD",
          E.BWR: "BWR", E.BRW: "BRW", E.ARMW: "ARMW", E.FRMW: "FRMW"}


def _read_mailboxes_full(escs: Sequence[E.Esc]) -> tuple[bool, ...]:
    """Whether each ESC's read mailbox (a mailbox SyncManager the slave writes) is full."""
    return tuple(any(s.enabled and s.mailbox and not s.master_writes and s.full
                     for s in esc.sm) for esc in escs)


def first_datagram(buf: bytearray, logical: bool) -> tuple[int, int] | None:
    """``(command, offset of its working counter)`` of the frame's first datagram (its
    first logical one when ``logical``), or None."""
    if len(buf) < 16 or (buf[14] | buf[15] << 8) >> 12 != 1:
        return None
    end = min(16 + ((buf[14] | buf[15] << 8) & 0x7FF), len(buf))
    pos = 16
    while pos + 12 <= end:
        length = (buf[pos + 6] | buf[pos + 7] << 8) & 0x7FF
        wkc_at = pos + 10 + length
        if wkc_at + 2 > end:
            return None
        if not logical or buf[pos] in _LOGICAL:
            return buf[pos], wkc_at
        if not buf[pos + 7] & 0x80:
            return None
        pos = wkc_at + 2
    return None


class EthercatFaults:
    """What the ``ethercat`` wire faults do to one segment's frames and cycles."""

    def __init__(self, line: Segment, wire: WireFaults) -> None:
        self.line = line
        self.wire = wire
        self._lock = threading.Lock()
        #: The per-frame faults live now (published by the model's thread).
        self._live: tuple[ActiveFault, ...] = ()
        #: What the frame thread did, for the model's thread to record.
        self._done: list[tuple[ActiveFault, str]] = []
        self._mailboxes: tuple[bool, ...] = ()
        #: Frames the faults saw (the frame thread), and what they did to them.
        self.frames = 0
        self.lost = 0
        self.changed = 0
        #: The late cycle running now: cycles due before it are skipped.
        self._late_until: int | None = None
        self.skipped = 0
        self._unwatch = wire.watch(DOOR, self._lasting)
        self._unwatch_every = wire.watch(DOOR, self._window, every_kind=True)
        for fault in wire.live_faults(DOOR):       # a machine file's, live from power-up
            if fault.lasting:
                self._lasting(fault, True)
        self._publish()

    def close(self) -> None:
        self._unwatch()
        self._unwatch_every()
        self.line.tap = None

    # -- the model's thread ---------------------------------------------------------------
    def _window(self, fault: ActiveFault, on: bool) -> None:
        """A fault of this door enters or leaves its window: the frames see it now."""
        if fault.kind in FRAME_KINDS:
            self._publish()

    def _publish(self) -> None:
        """Hand the per-frame faults live now to the frame thread (the model's thread):
        the tap is installed only while one is live."""
        live = tuple(f for f in self.wire.live_faults(DOOR) if f.kind in FRAME_KINDS)
        with self._lock:
            self._live = live
        self.line.tap = self.tap if live else None

    def sync(self) -> None:
        """Record what the frame thread did since the last call, and end the faults whose
        ``count`` it spent (the model's thread, each bridge cycle)."""
        if not self._done:
            return                                     # the fast path: nothing to do
        with self._lock:
            done, self._done = self._done, []
        for fault, text in done:
            self.wire.record(fault, text)
            if fault.spent and not fault.over:
                self.wire.clear(fault.id)

    def late_cycle(self) -> int | None:
        """The instant (ns) this cycle runs at instead of now, or None: run it now.
        A cycle due while a late one waits, or at the very instant it runs, is skipped
        (``0``): one cycle an instant."""
        now = self.wire.kernel.now
        if self._late_until is not None:
            if now <= self._late_until:
                self.skipped += 1
                return 0
            self._late_until = None
        if not self.wire.live(DOOR):
            return None
        fault = self.wire.hit(DOOR, ("late_cycle",))
        if fault is None:
            return None
        late = round(float(fault.params.get("ms", 3.0)) * NS_PER_MS)
        if late <= 0:
            return None
        self._late_until = now + late
        self.wire.record(fault, f"the bridge cycle due at {now / 1e6:.3f} ms starts "
                                f"{late / 1e6:g} ms late")
        return now + late

    def _lasting(self, fault: ActiveFault, on: bool) -> None:
        """``link_down`` begins or ends (the model's thread): the cable out or back."""
        if fault.kind != "link_down":
            return
        position = int(fault.params.get("bridge", 1)) - 1
        if position >= len(self.line.escs):
            self.wire.record(fault, f"no bridge {position + 1} on this segment "
                                    f"(1..{len(self.line.escs)}): nothing pulled")
            return
        if on:
            self.line.unplug(position)
            self.wire.record(fault, f"the cable into bridge {position + 1}'s port 0 "
                                    "is pulled")
            return
        if any(f.kind == "link_down" and f is not fault
               and int(f.params.get("bridge", 1)) - 1 == position
               for f in self.wire.live_faults(DOOR) if f.lasting):
            return                                     # another fault holds it down
        self.line.plug(position)
        self.wire.record(fault, f"the cable into bridge {position + 1}'s port 0 is back")

    # -- the frame thread -----------------------------------------------------------------
    def tap(self, position: int, buf: bytearray) -> bytearray | None:
        """The segment's tap (:attr:`~..engine.segment.Segment.tap`): the frame at the
        port 0 of the ESC at ``position``, or leaving for the master (``RETURNED``)."""
        live = self._live
        if position == 0:
            self.frames += 1
            if any(f.kind == "mailbox_lost" for f in live):
                self._mailboxes = _read_mailboxes_full(self.line.escs)
        if position != RETURNED:
            for fault in live:
                if fault.kind == "lost_frame" and fault.params.get("way") == "out" \
                        and int(fault.params.get("bridge", 1)) - 1 == position \
                        and fault.decide():
                    self._lose(fault, f"frame {self.frames} lost on its way to "
                               f"bridge {position + 1}'s port 0")
                    return None
            return buf
        for fault in live:
            if fault.kind == "lost_frame":
                if fault.params.get("way") == "back" and fault.decide():
                    self._lose(fault, f"frame {self.frames} lost on its way back "
                               "to the master")
                    return None
            elif fault.kind == "mailbox_lost":
                emptied = self._emptied(int(fault.params.get("bridge", 0)))
                if emptied and fault.decide():
                    self._lose(fault, f"frame {self.frames} lost on its way back: "
                               f"bridge {emptied}'s mailbox answer (SM1 "
                               "emptied) never reaches the master")
                    return None
            elif fault.kind == "wkc":
                found = first_datagram(buf, fault.params.get("datagram") != "any")
                if found is not None and fault.decide():
                    self._change_wkc(fault, buf, *found)
        return buf

    def _emptied(self, bridge: int) -> int:
        """The first bridge (1-based; ``bridge`` only, 0 any) whose read mailbox this
        frame emptied, or 0."""
        before = self._mailboxes
        after = _read_mailboxes_full(self.line.escs[:len(before)])
        for n, (was, now) in enumerate(zip(before, after), 1):
            if was and not now and bridge in (0, n):
                return n
        return 0

    def _lose(self, fault: ActiveFault, text: str) -> None:
        self.lost += 1
        with self._lock:
            self._done.append((fault, text))

    def _change_wkc(self, fault: ActiveFault, buf: bytearray, cmd: int, at: int) -> None:
        old = buf[at] | buf[at + 1] << 8
        new = (old + int(fault.params.get("delta", -1))) & 0xFFFF
        buf[at], buf[at + 1] = new & 0xFF, new >> 8
        self.changed += 1
        with self._lock:
            self._done.append((fault, f"frame {self.frames}: {_NAMES.get(cmd, hex(cmd))} "
                                      f"working counter {old} -> {new}"))
