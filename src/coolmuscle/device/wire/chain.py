"""Who the host reaches while the ``chain`` door's wire faults hold (chain/power.py).

A chained motor relays what passes between ID1 and the motors beyond it (ID n's COM1 is
wired to ID n+1's COM0, cml-users-guide.txt 1.1): a motor powered off or a broken link
cuts off every ID from there on, for the host line and for the Modbus doors behind
COM0 alike (docs/fidelity.md "Wire faults").
"""

from __future__ import annotations

from .schedule import WireFaults

__all__ = ["cut_from"]


def cut_from(faults: WireFaults) -> int:
    """The first ID the host cannot reach now (0: it reaches every motor): motor N
    powered off cuts N on, the link from N to N+1 broken cuts N+1 on."""
    first = 0
    for fault in faults.live_faults("chain"):
        if fault.motor is None:
            continue
        cut = fault.motor if fault.kind == "power_off" else fault.motor + 1
        first = cut if not first else min(first, cut)
    return first
