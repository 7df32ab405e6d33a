"""The state changes both KickCAT masters make (ETG.1000.6 ESM): SAFE-OP, then OP with
process data exchanged while waiting (the slave's SM watchdog needs it), then INIT."""

from __future__ import annotations

from datetime import timedelta
from typing import Any

import kickcat


def connect(iface: str) -> Any:
    """A bus on ``iface``, scanned."""
    link = kickcat.create_link(iface, "")
    # a loaded CI machine: answers may take more than 10 ms
    link.set_timeout(timedelta(milliseconds=50))
    bus = kickcat.Bus(link)
    bus.init(timedelta(seconds=2))
    return bus


def safe_op(bus: Any, slave: Any) -> str:
    """Map the process data and go to SAFE-OP; the state reached."""
    bus.create_mapping(4096)
    bus.request_state(kickcat.State.SAFE_OP)
    bus.wait_for_state(kickcat.State.SAFE_OP, timedelta(seconds=2))
    return str(bus.get_state(slave))


def operational(bus: Any, slave: Any) -> str:
    """Zero outputs, then OP while exchanging process data; the state reached."""
    def exchange(*_a: object) -> None:
        bus.process_data_no_check()

    slave.set_output_bytes(bytes(24))
    bus.request_state(kickcat.State.OPERATIONAL)
    bus.wait_for_state(kickcat.State.OPERATIONAL, timedelta(seconds=2), exchange)
    return str(bus.get_state(slave))


def init(bus: Any, slave: Any) -> str:
    """Back to INIT; the state reached."""
    bus.request_state(kickcat.State.INIT)
    bus.wait_for_state(kickcat.State.INIT, timedelta(seconds=2))
    return str(bus.get_state(slave))
