"""A second, independent master (KickCAT's Python binding) against the bridge: prints JSON.

``python kickcat_master.py IFACE CYCLES``: scan, SDO read of 1008h, mapping, SAFE-OP,
OP, process data each millisecond (ID1's target position = the cycle number), INIT.
"""

from __future__ import annotations

import json
import struct
import sys
import time
from datetime import timedelta

import kickcat


def main() -> None:
    link = kickcat.create_link(sys.argv[1], "")
    link.set_timeout(timedelta(milliseconds=50))   # a loaded CI machine: answers may take more than 10 ms
    bus = kickcat.Bus(link)
    bus.init(timedelta(seconds=2))
    slaves = bus.slaves()
    s = slaves[0]
    res = {"found": len(slaves), "address": s.address,
           "sdo_1008": bus.read_sdo(s, 0x1008, 0, kickcat.Access.PARTIAL, 64,
                                    timedelta(seconds=1)).decode("latin-1"),
           "vendor": struct.unpack("<I", bus.read_sdo(s, 0x1018, 1, kickcat.Access.PARTIAL, 4,
                                                      timedelta(seconds=1)))[0]}
    bus.create_mapping(4096)
    res["in_size"], res["out_size"] = s.input_size, s.output_size
    bus.request_state(kickcat.State.SAFE_OP)
    bus.wait_for_state(kickcat.State.SAFE_OP, timedelta(seconds=2))
    res["safeop"] = str(bus.get_state(s))

    def exchange(*_a: object) -> None:
        bus.process_data_no_check()

    s.set_output_bytes(bytes(24))
    bus.request_state(kickcat.State.OPERATIONAL)
    bus.wait_for_state(kickcat.State.OPERATIONAL, timedelta(seconds=2), exchange)
    res["op"] = str(bus.get_state(s))
    errors = 0
    inputs = []
    for i in range(int(sys.argv[2])):
        s.set_output_bytes(struct.pack("<Hi", 0x0006, 1000 + i) + bytes(18))
        try:
            bus.process_data()
        except Exception:
            errors += 1
        inputs.append(bytes(s.input_data).hex())
        time.sleep(0.001)
    res["errors"] = errors
    res["last_input"] = inputs[-1]
    res["last_target"] = 1000 + int(sys.argv[2]) - 1
    bus.request_state(kickcat.State.INIT)
    bus.wait_for_state(kickcat.State.INIT, timedelta(seconds=2))
    res["init"] = str(bus.get_state(s))
    print(json.dumps(res))


if __name__ == "__main__":
    main()
