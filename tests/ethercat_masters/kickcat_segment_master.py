"""KickCAT (a second, independent master) scans several bridges in a line: prints JSON.

``python kickcat_segment_master.py IFACE CYCLES``: scan, each slave's address and
1008h/1018h over SDO, one mapping of every slave's process data, SAFE-OP, OP with
process data (bridge n's ID1 target = 1000 n + the cycle), INIT.
"""

from __future__ import annotations

import json
import struct
import sys
import time
from datetime import timedelta

import kickcat
from kickcat_states import connect


def main() -> None:
    bus = connect(sys.argv[1])
    slaves = bus.slaves()

    def sdo(s, index: int, sub: int, size: int) -> bytes:
        return bus.read_sdo(s, index, sub, kickcat.Access.PARTIAL, size, timedelta(seconds=1))

    res: dict = {"found": len(slaves), "addresses": [s.address for s in slaves],
                 "sdo_1008": [sdo(s, 0x1008, 0, 64).decode("latin-1") for s in slaves],
                 "product": [struct.unpack("<I", sdo(s, 0x1018, 2, 4))[0] for s in slaves]}
    bus.create_mapping(4096)
    res["sizes"] = [[s.input_size, s.output_size] for s in slaves]
    bus.request_state(kickcat.State.SAFE_OP)
    bus.wait_for_state(kickcat.State.SAFE_OP, timedelta(seconds=2))
    res["safeop"] = [str(bus.get_state(s)) for s in slaves]

    def exchange(*_a: object) -> None:
        bus.process_data_no_check()

    for s in slaves:
        s.set_output_bytes(bytes(24))
    bus.request_state(kickcat.State.OPERATIONAL)
    bus.wait_for_state(kickcat.State.OPERATIONAL, timedelta(seconds=2), exchange)
    res["op"] = [str(bus.get_state(s)) for s in slaves]
    errors = 0
    cycles = int(sys.argv[2])
    for i in range(cycles):
        for n, s in enumerate(slaves):
            s.set_output_bytes(struct.pack("<Hi", 0x0006, 1000 * (n + 1) + i) + bytes(18))
        try:
            bus.process_data()
        except Exception:
            errors += 1
        time.sleep(0.001)
    res["errors"] = errors
    res["last_inputs"] = [bytes(s.input_data).hex() for s in slaves]
    res["last_targets"] = [1000 * (n + 1) + cycles - 1 for n in range(len(slaves))]
    bus.request_state(kickcat.State.INIT)
    bus.wait_for_state(kickcat.State.INIT, timedelta(seconds=2))
    res["init"] = [str(bus.get_state(s)) for s in slaves]
    print(json.dumps(res))


if __name__ == "__main__":
    main()
