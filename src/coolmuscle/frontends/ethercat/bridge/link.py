"""The CM port between the bridge and one Cool Muscle, in virtual time
(ethercat-bridge-users-guide.txt 2.2, 7.3 F511h-F514h, 7.4 F530h).

The real bridge talks to each motor over a serial line at 176,800 bps with a 1 ms
cycle.  Nothing of the motor is modelled here: :class:`CmLink` only says when bytes
sent at a given instant have crossed the line (10 bits a byte, one frame after the
other in each direction) and counts what crossed it, for the F530h transmission,
receive and receive-error counters.  :class:`PdoCycleStats` keeps the F530h.11-.14
figures of the intervals between received RxPDO images.
"""

from __future__ import annotations

import threading
from _thread import LockType
from dataclasses import dataclass, field
from typing import Final

#: 7.3 F511h.2 "6: 176,800bps" and F511h.3 "1: 1 msec" (the codes the objects read).
BAUD: Final = 176_800
BAUD_CODE: Final = 6
CYCLE_CODE: Final = 1
CYCLE_NS: Final = 1_000_000
BITS_PER_BYTE: Final = 10                    # start, 8 data, stop
BYTE_NS: Final = BITS_PER_BYTE * 1_000_000_000 // BAUD      # 56,561 ns


@dataclass
class CmLink:
    """One CM port: when bytes arrive, and the F530h counters of its axis."""

    transmissions: int = 0            # F530h.9-.C "Serial Communication; Transmission Count"
    receptions: int = 0               # F530h.D-.10 "Serial Communication; Receive Count"
    receive_errors: int = 0           # F530h.1-.4 "Receive Error Counter"
    _tx_free: int = 0                 # the instant each direction is free again
    _rx_free: int = 0

    def send(self, nbytes: int, now: int) -> int:
        """Bridge -> motor: ``nbytes`` queued at ``now`` have arrived at the returned ns."""
        start = max(now, self._tx_free)
        self._tx_free = start + nbytes * BYTE_NS
        self.transmissions += 1
        return self._tx_free

    def receive(self, nbytes: int, now: int) -> int:
        """Motor -> bridge: a frame of ``nbytes`` sent at ``now`` has arrived at the returned ns."""
        start = max(now, self._rx_free)
        self._rx_free = start + nbytes * BYTE_NS
        self.receptions += 1
        return self._rx_free

    def cycle(self, now: int, command_bytes: int, status_bytes: int) -> None:
        """The cyclic exchange of one bridge cycle: a command out, the status back."""
        arrived = self.send(command_bytes, now)
        self.receive(status_bytes, arrived)


@dataclass
class PdoCycleStats:
    """F530h.11-.14: max/min interval between RxPDO images (us), and the counts of
    intervals over 1,300 us and under 700 us.  Fed from the frame thread."""

    max_us: int = 0
    min_us: int = 0
    over_1300: int = 0
    under_700: int = 0
    _last_ns: int | None = None
    # _thread.LockType: the lock's class (threading.Lock is a function; compiled code
    # checks the attribute's class)
    _lock: LockType = field(default_factory=threading.Lock, repr=False)

    def received(self, t_ns: int) -> None:
        with self._lock:
            last, self._last_ns = self._last_ns, t_ns
            if last is None:
                return
            us = max(0, (t_ns - last) // 1000)
            self.max_us = max(self.max_us, us)
            self.min_us = us if self.min_us == 0 else min(self.min_us, us)
            self.over_1300 += us > 1300
            self.under_700 += us < 700

    def restart(self) -> None:
        """OP left: the next image starts a new series."""
        with self._lock:
            self._last_ns = None
