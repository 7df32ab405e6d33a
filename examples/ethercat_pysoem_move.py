"""Move a virtual Cool Muscle from a real EtherCAT master (SOEM through pysoem).

    coolmuscle ethercat lab run -- python examples/ethercat_pysoem_move.py cmlab-master

(no root needed: a lab of its own, docs/ethercat.md; as root after ``coolmuscle ethercat
lab up`` and ``ip netns exec coolmuscle-lab coolmuscle sim --ethercat cmlab-slave &``,
``python examples/ethercat_pysoem_move.py cmlab-master``.)

Brings the bridge to OP, enables ID1 (controlwords 06h, 07h, 0Fh: manual 6.1.2) and
moves it 4,000 pulses in csp (one target a millisecond, 6.3), printing 6041h and
6064h from the TxPDO.  docs/ethercat.md has the other modes.
"""

from __future__ import annotations

import struct
import sys
import time

import pysoem


def main(iface: str) -> None:
    master = pysoem.Master()
    master.open(iface)
    try:
        if master.config_init() != 1:
            raise SystemExit("no bridge found on " + iface)
        bridge = master.slaves[0]
        master.config_map()                                  # 24 bytes out, 24 in (6.3.1)
        master.state = pysoem.OP_STATE
        master.write_state()
        cw, target = 0x0000, 0

        def cycle() -> tuple[int, int]:
            bridge.output = struct.pack("<Hi", cw, target) + bytes(18)   # ID1 only
            master.send_processdata()
            master.receive_processdata(10_000)
            time.sleep(0.001)
            return struct.unpack_from("<Hi", bytes(bridge.input))      # 6041h, 6064h

        while master.state_check(pysoem.OP_STATE, 5000) != pysoem.OP_STATE:
            cycle()
        status, position = cycle()
        target = position
        for cw in (0x06, 0x07, 0x0F):                        # to Operation enabled
            for _ in range(10):
                status, position = cycle()
            print(f"controlword {cw:#06x}: statusword {status:#06x}")
        start = position
        for i in range(1, 2001):                             # 2 s ramp of 4,000 pulses
            target = start + 2 * i
            status, position = cycle()
        for _ in range(300):
            status, position = cycle()
        print(f"target {target}, 6064h {position}, statusword {status:#06x}")
        master.state = pysoem.INIT_STATE
        master.write_state()
    finally:
        master.close()


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "cmlab-master")
