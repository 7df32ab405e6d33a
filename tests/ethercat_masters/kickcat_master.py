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
from kickcat_states import connect, init, operational, safe_op


def main() -> None:
    bus = connect(sys.argv[1])
    slaves = bus.slaves()
    s = slaves[0]
    res = {"found": len(slaves), "address": s.address,
           "sdo_1008": bus.read_sdo(s, 0x1008, 0, kickcat.Access.PARTIAL, 64,
                                    timedelta(seconds=1)).decode("latin-1"),
           "vendor": struct.unpack("<I", bus.read_sdo(s, 0x1018, 1, kickcat.Access.PARTIAL, 4,
                                                      timedelta(seconds=1)))[0]}
    res["safeop"] = safe_op(bus, s)
    res["in_size"], res["out_size"] = s.input_size, s.output_size
    res["op"] = operational(bus, s)
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
    res["init"] = init(bus, s)
    print(json.dumps(res))


if __name__ == "__main__":
    main()
