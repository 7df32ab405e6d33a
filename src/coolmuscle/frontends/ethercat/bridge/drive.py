"""The drive behind the bridge: four :class:`~.axis.AxisDrive`, their CM ports and
mailboxes (ethercat-bridge-users-guide.txt chapters 6 and 7).

:class:`BridgeDrive` is what :class:`~.app.BridgeApp` runs each bridge cycle (in
the model's thread): for every axis the cyclic CM-port exchange (counted on its
:class:`~.link.CmLink`), the CML mailbox, then the axis.  It is a client of the
motor model through the device API only.  ``outputs_received`` and
``safe_outputs`` come from the frame thread.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Final

from ....device import Device, Event
from ..engine.dictionary import Dictionary
from ..engine.od import Entry
from . import bridge_objects
from .axis import AxisDrive
from .cml_mailbox import CmlMailbox
from .link import CmLink, PdoCycleStats

log = logging.getLogger(__name__)

#: Bytes of the cyclic exchange on the CM port (the manual does not give its frame):
#: a position command out, a status back (docs/fidelity.md "EtherCAT drive").
COMMAND_BYTES: Final = 8
STATUS_BYTES: Final = 8
#: K parameters re-read from each motor per cycle (the cache of the 60F6h reads).
K_REFRESH_PER_CYCLE: Final = 1
LATE_NS: Final = 1_500_000


def _k_entries(od: Dictionary, motor: int) -> tuple[Entry, ...]:
    """The entries of 60F6h (K21-K99, Appendix 6) of axis ``motor``."""
    obj = od.table.get(0x60F6 + 0x800 * (motor - 1))
    assert obj is not None                 # every axis has it (table.py)
    return obj.entries


class BridgeDrive:
    """CiA402 and the Cool Muscle modes for the motors of one bridge."""

    def __init__(self, device: Device, od: Dictionary, firmware: tuple[str, ...], axes: list[int],
                 clock: Callable[[], int] = time.monotonic_ns) -> None:
        self.device = device
        self.od = od
        self.firmware = firmware
        self.clock = clock
        self.links = {n: CmLink() for n in axes}
        self.mailboxes = {n: CmlMailbox(n, self.links[n]) for n in axes}
        self.axes = {n: AxisDrive(n, firmware[n - 1], device, od) for n in axes}
        self.pdo = PdoCycleStats()
        self.cycles = 0
        self.late_cycles = 0               # cycles that came more than 1.5 ms after the last
        self.max_gap_ns = 0                # the longest interval between two cycles
        self._last_cycle: int | None = None
        self._k_order = [(n, e.sub + 20) for n in axes for e in _k_entries(od, n)
                         if e.sub and e.available] + [(n, 37) for n in axes]
        self._k_next = 0
        for n in axes:
            self._load_k(self.axes[n])
        self._unsubscribe = device.subscribe(self._event)
        bridge_objects.register(self)

    def _load_k(self, axis: AxisDrive) -> None:
        for n, k in self._k_order:
            if n == axis.motor:
                self._read_k(axis, k)
        for k in (42, 43, 45, 46, 48):
            self._read_k(axis, k)
        speed = axis.k.get(42, 1)
        self.od.set(axis.idx(0x6099), 1, speed)
        self.od.set(axis.idx(0x6099), 2, speed)
        if axis.firmware != "cm1":
            try:
                axis.h0 = int(self.device.get_register(axis.motor, "H", 0))
            except Exception:
                log.debug("ID%d: no H0", axis.motor)

    def _read_k(self, axis: AxisDrive, k: int) -> None:
        try:
            axis.k[k] = self.device.get_param(axis.motor, k)
        except Exception:
            log.debug("ID%d: no K%d", axis.motor, k)

    def _event(self, event: Event) -> None:
        mailbox = self.mailboxes.get(event.motor)
        if mailbox is not None:
            mailbox.on_event(event)

    # -- model thread -------------------------------------------------------------
    def cycle(self) -> None:
        """One bridge cycle (6.3: 1 ms)."""
        now = self.device.kernel.now
        self._count(now)
        for n, axis in self.axes.items():
            self.links[n].cycle(now, COMMAND_BYTES, STATUS_BYTES)
            self.mailboxes[n].pump(self.device, now)
            axis.cycle(now)
        self._refresh_k()

    def _count(self, now: int) -> None:
        """The cycle's own timing: a late cycle is a CM-port cycle the bridge missed."""
        self.cycles += 1
        if self._last_cycle is not None:
            gap = now - self._last_cycle
            self.max_gap_ns = max(self.max_gap_ns, gap)
            self.late_cycles += gap > LATE_NS
        self._last_cycle = now

    def _refresh_k(self) -> None:
        order = self._k_order
        if not order:
            return
        for _ in range(K_REFRESH_PER_CYCLE * len(self.axes)):
            n, k = order[self._k_next % len(order)]
            self._k_next += 1
            axis = self.axes[n]
            if not axis.requests:          # a queued write is newer than the motor's value
                self._read_k(axis, k)

    def close(self) -> None:
        self._unsubscribe()

    # -- frame thread ---------------------------------------------------------------
    def outputs_received(self) -> None:
        self.pdo.received(self.clock())

    def safe_outputs(self) -> None:
        self.pdo.restart()
        for axis in self.axes.values():
            axis.requests.append(axis.outputs_lost)

    def system_info(self, sub: int) -> int:
        """F530h (7.4)."""
        if sub == 0:
            return 0x18
        group, n = divmod(sub - 1, 4)
        n += 1
        link, axis = self.links.get(n), self.axes.get(n)
        if group == 0:
            return link.receive_errors if link else 0
        if group == 1:
            return (axis.ux & 0xFF) if axis else 0
        if group == 2:
            return link.transmissions & 0xFFFFFFFF if link else 0
        if group == 3:
            return link.receptions & 0xFFFFFFFF if link else 0
        if group == 4:
            p = self.pdo
            return (p.max_us, p.min_us, p.over_1300, p.under_700)[n - 1]
        return 0
