"""Several bridges on one EtherCAT segment, as a machine built with them has them.

A machine with more axes than one bridge carries (four, manual 1.4) has bridges in a
line: a 12-axis gantry three, a 32-axis line eight.  :class:`BridgeSegment` holds one
:class:`~.app.BridgeApp` per bridge, each with its own variant (EB01, EB02, EB12), SII,
object dictionary, AL status and station address, and each served from its own chain
of the model (the motors behind its CM ports, ID1-ID4); their ESCs stand in a line
(:class:`~..engine.segment.Segment`: port 0 towards the master, port 1 towards the next
bridge, the last one closing the ring).

All the chains run on **one kernel**: the machine has one virtual time, so every
bridge's cycle at t ms runs before anything at a later instant, a paced kernel falls
behind (or keeps up) for the whole machine at once, and one real-time driver paces it
(a kernel per bridge would need as many drivers stepping side by side, their clocks
apart by whatever each step took).  The bridges' cycles are one kernel event a
millisecond that runs the bridges in line order: each bridge still gets its cycle on
its own CM port's grid (6.3), and the bridges' motors never meet, so what one axis
does does not depend on the others (nor on how many bridges there are).

:meth:`BridgeSegment.unplug` pulls the cable into a bridge's port 0: that bridge and
everything behind it leave the segment (the frames come back from the bridge in front),
their SM watchdogs expire (OP -> SAFE-OP + 001Bh) while their motors go on running;
:meth:`BridgeSegment.plug` puts it back, and a master's new start-up reaches OP again.

The ``ethercat`` wire faults (docs/wire-faults.md) are the first device's
(:attr:`BridgeSegment.faults`, :mod:`.faults`): each cycle publishes the live ones to
the frames' tap and may start late.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

from ....device import Device
from ....sim.kernel import PRIO_IO, Timer
from ..engine.segment import Segment
from .app import CYCLE_NS, BridgeApp, CycleSchedule
from .faults import EthercatFaults

log = logging.getLogger(__name__)


class BridgeSegment:
    """Bridges ``codes`` (line order) served from ``devices`` (one chain each, or None
    for a bridge that answers with its dictionary only)."""

    def __init__(self, devices: Sequence[Device | None], codes: Sequence[str]) -> None:
        if len(devices) != len(codes) or not codes:
            raise ValueError("a segment needs one device per bridge, and a bridge at least")
        kernels = {id(d.kernel) for d in devices if d is not None}
        if len(kernels) > 1:
            raise ValueError("the bridges of a segment run on one kernel (one virtual time)")
        self.apps = tuple(BridgeApp(d, c) for d, c in zip(devices, codes))
        self.line = Segment([app.stack.esc for app in self.apps])
        self.device = next((d for d in devices if d is not None), None)
        self._cycles: CycleSchedule | None = None
        self._late: Timer | None = None           # a late cycle waiting to run
        #: The ``ethercat`` wire faults (none without a device: no virtual time).
        self.faults = None if self.device is None \
            else EthercatFaults(self.line, self.device.wire_faults)

    def __len__(self) -> int:
        return len(self.apps)

    # -- the model's thread -------------------------------------------------------------
    def cycle(self) -> None:
        """One bridge cycle of every bridge, in line order (a failing one is logged and
        the others still run); a ``late_cycle`` wire fault runs it later."""
        faults = self.faults
        if faults is not None:
            faults.sync()
            later = faults.late_cycle()
            if later is not None:
                if later and self.device is not None:
                    self._late = self.device.kernel.schedule_at(
                        later, self._run_apps, priority=PRIO_IO, name="late bridge cycle")
                return
        self._run_apps()

    def _run_apps(self) -> None:
        for position, app in enumerate(self.apps, 1):
            try:
                app.cycle()
            except Exception:
                log.exception("bridge %d (%s): cycle failed", position, app.variant.code)

    def start_cycles(self, period_ns: int = CYCLE_NS,
                     on_start: Callable[[], None] | None = None) -> None:
        """:meth:`cycle` every ``period_ns`` of virtual time on the segment's kernel
        (one event for every bridge; :meth:`.app.BridgeApp.start_cycles` says why the
        cycles are kernel events).  Starting again replaces the schedule."""
        self.stop_cycles()
        if self.device is None:
            raise RuntimeError("the bridge cycles run on a device's kernel: none was given")
        self._cycles = CycleSchedule(self.device.kernel, period_ns, self.cycle, on_start)

    def stop_cycles(self) -> None:
        if self._late is not None:
            self._late.cancel()
            self._late = None
        if self._cycles is not None:
            self._cycles.cancel()
            self._cycles = None

    def close(self) -> None:
        """Stop the cycles and let the device's wire faults go (the model's thread)."""
        self.stop_cycles()
        if self.faults is not None:
            self.faults.close()

    # -- the cables (any thread) ----------------------------------------------------------
    def unplug(self, bridge: int) -> None:
        """Pull the cable into bridge ``bridge``'s port 0 (1 = next to the master)."""
        self.line.unplug(self._position(bridge))

    def plug(self, bridge: int) -> None:
        """Put the cable into bridge ``bridge``'s port 0 back."""
        self.line.plug(self._position(bridge))

    def _position(self, bridge: int) -> int:
        if not 1 <= bridge <= len(self.apps):
            raise ValueError(f"no bridge {bridge} on the segment (1..{len(self.apps)})")
        return bridge - 1
