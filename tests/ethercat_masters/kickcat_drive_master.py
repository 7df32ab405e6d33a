"""KickCAT (a second, independent master) drives the bridge's axes: prints JSON.

``python kickcat_drive_master.py IFACE``: SDO reads of the drive's objects (6502h,
6061h, 60E3h, F511h, F591h: ethercat-bridge-users-guide.txt 6.2, 6.4.1, 7.2, 7.3),
OP, controlwords 06h/07h/0Fh on all four axes (6.1.2), a 0.5 s csp move of 1,000
pulses on every axis (6.3), then F530h.9 (7.4).  KickCAT's binding reads SDOs only.
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
    s = bus.slaves()[0]

    def sdo(index: int, sub: int, size: int) -> bytes:
        return bus.read_sdo(s, index, sub, kickcat.Access.PARTIAL, size, timedelta(seconds=1))

    res = {"6502": struct.unpack("<I", sdo(0x6502, 0, 4))[0],
           "6061": [struct.unpack("<b", sdo(0x6061 + 0x800 * a, 0, 1))[0] for a in range(4)],
           "60e3": [struct.unpack("<H", sdo(0x60E3, k, 2))[0] for k in range(1, 5)],
           "f511": [struct.unpack("<I", sdo(0xF511, k, 4))[0] for k in range(1, 4)],
           "f591": sdo(0xF591, 0, 64).decode("latin-1")}
    safe_op(bus, s)
    res["op"] = operational(bus, s)
    cw, target = [0] * 4, [0] * 4
    words, pos = [0] * 4, [0] * 4

    def cycle(n: int) -> None:
        nonlocal words, pos
        for _ in range(n):
            s.set_output_bytes(b"".join(struct.pack("<Hi", c, t) for c, t in zip(cw, target)))
            try:
                bus.process_data()
            except Exception:
                pass
            data = bytes(s.input_data)
            words = [struct.unpack_from("<H", data, 6 * a)[0] for a in range(4)]
            pos = [struct.unpack_from("<i", data, 6 * a + 2)[0] for a in range(4)]
            time.sleep(0.001)

    cycle(20)
    target = list(pos)
    start = list(pos)
    for word in (0x06, 0x07, 0x0F):
        cw = [word] * 4
        cycle(30)
        res[f"sw_{word:02x}"] = list(words)
    for i in range(1, 501):
        target = [p + 2 * i for p in start]
        cycle(1)
    cycle(400)
    res["start"], res["end"], res["sw_end"] = start, list(pos), list(words)
    res["f530_tx"] = struct.unpack("<I", sdo(0xF530, 9, 4))[0]
    init(bus, s)
    print(json.dumps(res))


if __name__ == "__main__":
    main()
