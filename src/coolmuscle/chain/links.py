"""The links between daisy-chained motors: wire time at the chain baud rate K65.

The host line enters at ID1; ID1's COM1 is wired to ID2's COM0, and so on (cml-users-
guide.txt 1.1, ch. 3 K65 "the baud rate between slave motors in the daisy chain
operation").  With wire-time pacing on, a command for ID n reaches it after n-1 hops and
a reply from ID n comes back the same way: each hop carries the bytes after the motor
before it has received them all (store and forward), 10 bits a byte at the K65 rate,
and a link carries one message at a time in each direction.  So a command reaches a
farther motor later, and motors started by one line start the later the farther they
are (ch. 3 K65: "When setting a high baud rate, the synchronization will be better").

The model never sleeps: arrivals are instants (ns) the chain schedules kernel events at.
The choices made where the manual is silent are in docs/fidelity.md "Daisy chain".
"""

from __future__ import annotations

from collections.abc import Callable

from ..device.hostline import BAUD_RATES, byte_time_ns


class ChainLinks:
    """Store-and-forward wire time between motors 1..N, both directions."""

    def __init__(self, motors: int, k65: Callable[[], int]) -> None:
        self.motors = motors
        self._k65 = k65
        # link k joins ID k and ID k+1; when each direction is free again (ns)
        self._down_free = [0] * (motors + 1)
        self._up_free = [0] * (motors + 1)
        self.bytes_relayed = 0

    def baud(self) -> int:
        """Bits per second of the chain (ID1's K65: it sets every link, ch. 3 K65)."""
        return BAUD_RATES.get(self._k65(), 38400)

    def hop_ns(self, nbytes: int) -> int:
        """Wire time of ``nbytes`` over one link."""
        return nbytes * byte_time_ns(self.baud())

    def arrival(self, src: int, dst: int, nbytes: int, start: int) -> int:
        """When ``nbytes`` sent by ID ``src`` at ``start`` have all reached ID ``dst``.

        IDs past the final motor (the COM1 device, 5.6.6) are reached through the
        final motor; its COM1 link is not a chain link.
        """
        src = min(max(src, 1), self.motors)
        dst = min(max(dst, 1), self.motors)
        t = start
        if dst == src or nbytes <= 0:
            return t
        duration = self.hop_ns(nbytes)
        if dst > src:
            for link in range(src, dst):
                t = max(t, self._down_free[link]) + duration
                self._down_free[link] = t
        else:
            for link in range(src - 1, dst - 1, -1):
                t = max(t, self._up_free[link]) + duration
                self._up_free[link] = t
        self.bytes_relayed += nbytes * abs(dst - src)
        return t
