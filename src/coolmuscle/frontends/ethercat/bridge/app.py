"""The bridge application: the four Cool Muscles behind the slave (manual 1.4, 6.3).

:class:`BridgeApp` is the slave stack's :class:`~..engine.slave.Application`.  It hands
the engine the bridge's slave description (:mod:`.description`), owns the object
dictionary built from its table, and the 1 ms cycle (:meth:`BridgeApp.cycle`, run in
the model's thread by the transport) that turns the output image into the drive of
:mod:`.drive` (CiA402 6.1, every mode of ch. 6 and 7) and the device API's cyclic
state into the input image (6041h, 6064h + 0x800 n), through
:class:`~..engine.dictionary.Dictionary` hooks and :meth:`outputs` / :meth:`cycle`,
without touching the ESC.

Thread rule (docs/architecture.md rule 2): :meth:`state_change`, :meth:`outputs`,
:meth:`safe_outputs` and the dictionary hooks run in the frame thread and must
not call the model; :meth:`cycle` runs in the model's thread.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

from ....device import Device
from ....sim.kernel import PRIO_IO, Timer
from ..engine import esm
from ..engine.dictionary import Dictionary, WriteHook
from ..engine.od import Table
from ..engine.slave import SlaveStack
from . import identity as ident
from .description import describe

if TYPE_CHECKING:
    from .drive import BridgeDrive

log = logging.getLogger(__name__)

AXIS_OFFSET = 0x800
#: 6.2 operation modes: hm 6, csp 8, CML 101, CMD 120, CPIO 121.
MODES = frozenset({6, 8, 101, 120, 121})
MODE_CSP = 8
#: 6.3, 7.3 F511h.3 "CM Serial Communication Cycle Time: 1. 1 msec": the bridge's own cycle.
CYCLE_NS = 1_000_000


class BridgeApp:
    """EB01/EB02/EB12 behind one slave stack, served from a device (a Chain of 4).

    Without a device (``None``) the slave answers on the wire with its dictionary only:
    no drive, no cycles (the sans-IO tests of the engine use it so)."""

    def __init__(self, device: Device | None, bridge: str = ident.DEFAULT_VARIANT) -> None:
        self.device = device
        self.variant = ident.variant(bridge)
        self.description = describe(self.variant.code)
        self.table: Table = self.description.table
        self.dictionary = Dictionary(self.table)
        self.stack = SlaveStack(self, self.description)
        ids = tuple(device.motor_ids) if device is not None else ()
        self.axes = [n for n in range(1, ident.AXES + 1) if n in ids]
        self.operational = False
        for axis in range(ident.AXES):
            self.dictionary.on_write(0x6060 + AXIS_OFFSET * axis, self._mode_written(axis))
        self.drive: BridgeDrive | None = None   # every mode of ch. 6 and 7 (drive.py)
        self._cycle_timer: Timer | None = None
        if device is not None:
            from .drive import BridgeDrive
            self.drive = BridgeDrive(device, self.dictionary, self.variant.firmware, self.axes)

    @staticmethod
    def _mode_written(axis: int) -> WriteHook:
        def hook(sub: int, value: int | str) -> int | None:
            """6.2.2 note 3: a mode that is not available is set to csp (8)."""
            return None if value in MODES else MODE_CSP
        return hook

    # -- frame thread ---------------------------------------------------------
    def state_change(self, current: int, requested: int) -> int:
        """Every valid transition is accepted (the CiA402 checks come with part 2)."""
        if requested == esm.OP:
            self.operational = True
        elif current == esm.OP:
            self.operational = False
        return 0

    def outputs(self, image: bytes) -> None:
        """An output image in OP: already in the dictionary (6040h/607Ah per axis)."""
        if self.drive is not None:
            self.drive.outputs_received()

    def safe_outputs(self) -> None:
        """OP left: the commands of the output image are no longer valid (6.3)."""
        self.operational = False
        if self.drive is not None:
            self.drive.safe_outputs()

    # -- model thread ---------------------------------------------------------------
    def cycle(self) -> None:
        """One bridge cycle: each axis's drive steps (6.1, 6.3), then the inputs go out."""
        od = self.dictionary
        if self.drive is not None:              # the modes of bridge/ run each axis
            self.drive.cycle()
        self.stack.set_inputs(od.pack_inputs())

    def start_cycles(self, period_ns: int = CYCLE_NS,
                     on_start: Callable[[], None] | None = None) -> None:
        """Run :meth:`cycle` every ``period_ns`` of virtual time, on the device's kernel.

        The bridge's CM port has its own fixed cycle (6.3, F511h.3: 1 ms): every motor
        gets a command each millisecond of its own time, whenever the master's frames
        come (a cycle reads the output image as it is then).  So the cycles are kernel
        events on an exact grid; a paced kernel runs them as the wall clock reaches
        them, several at once if the model fell behind, and none is lost.  ``on_start``
        runs at the start of each cycle, before it (the transport's lateness count).
        A cycle that raises is logged; the next one still comes.  Starting again
        replaces the schedule.
        """
        if period_ns <= 0:
            raise ValueError(f"the bridge cycle must be a positive time, not {period_ns} ns")
        self.stop_cycles()
        if self.device is None:
            raise RuntimeError("the bridge cycles run on a device's kernel: none was given")
        kernel = self.device.kernel

        def tick() -> None:
            self._cycle_timer = kernel.schedule_at(kernel.now + period_ns, tick,
                                                   priority=PRIO_IO, name="bridge cycle")
            try:
                if on_start is not None:
                    on_start()
                self.cycle()
            except Exception:
                log.exception("bridge cycle failed at %d ns", kernel.now)

        self._cycle_timer = kernel.schedule_at(kernel.now + period_ns, tick,
                                               priority=PRIO_IO, name="bridge cycle")

    def stop_cycles(self) -> None:
        """No more cycles from :meth:`start_cycles`."""
        if self._cycle_timer is not None:
            self._cycle_timer.cancel()
            self._cycle_timer = None
