"""SOEM (pysoem) as the master of several bridges in a line: prints JSON.

``python segment_master.py IFACE AXES`` (AXES: the axis, 0-3, that moves on each bridge,
comma-separated): scan (the slave count, names and identities), an SDO K write to the
second bridge, mapping, SAFE-OP, OP, 6.1.2's enable on every axis and a csp ramp on
the chosen axis of each bridge.  Then it prints ``READY`` and waits for a line on
stdin (the test pulls the cable into the second bridge), keeps cycling and reports
what it sees (the working counter, each slave's AL status, the first bridge's DL
status), prints ``READY`` again and waits (the test plugs it back), and starts over:
a new scan, mapping and OP, cycles, INIT.
"""

from __future__ import annotations

import json
import select
import struct
import sys
import time

import pysoem

K43_SUB = 43 - 20          # 60F6h subindex n is K(20 + n) (7.5)
K43_VALUE = 150


def identify(master) -> dict:
    return {"names": [s.name for s in master.slaves],
            "ids": [[s.man, s.id, s.rev] for s in master.slaves],
            "sdo_1008": [s.sdo_read(0x1008, 0).decode("latin-1") for s in master.slaves]}


def exchange(master, outputs: list[list[tuple[int, int]]]) -> tuple[int, list]:
    """One cycle: every slave's four (controlword, target); the working counter and
    every slave's four (statusword, position)."""
    for s, axes in zip(master.slaves, outputs):
        s.output = b"".join(struct.pack("<Hi", cw, t) for cw, t in axes)
    master.send_processdata()
    wkc = master.receive_processdata(10_000)
    time.sleep(0.001)
    return wkc, [[struct.unpack_from("<Hi", s.input, 6 * a) for a in range(4)]
                 for s in master.slaves]


def to_op(master) -> dict:
    out = {"iomap": master.config_map(),
           "sizes": [[len(s.output), len(s.input)] for s in master.slaves]}
    out["safeop"] = master.state_check(pysoem.SAFEOP_STATE, 500_000)
    master.state = pysoem.OP_STATE
    master.write_state()
    state = 0
    hold = [[(0, 0)] * 4 for _ in master.slaves]
    for _ in range(300):
        exchange(master, hold)
        state = master.state_check(pysoem.OP_STATE, 5000)
        if state == pysoem.OP_STATE:
            break
    out["op"] = state
    master.read_state()
    out["slave_states"] = [s.state for s in master.slaves]
    out["expected_wkc"] = master.expected_wkc
    return out


def enable_and_move(master, moving: list[int], steps: int) -> dict:
    """6.1.2 on every axis, then ``moving[n]`` of slave n ramps by 2 pulses a cycle."""
    _wkc, now = exchange(master, [[(0, 0)] * 4 for _ in master.slaves])
    start = [[p for _w, p in axes] for axes in now]
    words = {}
    for cw in (0x06, 0x07, 0x0F):
        for _ in range(30):
            _wkc, now = exchange(master, [[(cw, p) for p in pos] for pos in start])
        words[hex(cw)] = [[w for w, _p in axes] for axes in now]
    ok = 0
    targets = [list(pos) for pos in start]
    for i in range(steps + 300):
        for n, axis in enumerate(moving):
            targets[n][axis] = start[n][axis] + 2 * min(i + 1, steps)
        wkc, now = exchange(master, [[(0x0F, t) for t in tg] for tg in targets])
        ok += wkc == master.expected_wkc
    return {"words": words, "start": start, "targets": targets, "wkc_ok": ok,
            "cycles": steps + 300, "final": [[p for _w, p in axes] for axes in now],
            "final_words": [[w for w, _p in axes] for axes in now]}


def wait_for_the_test(master, hold: list[list[tuple[int, int]]]) -> None:
    """Say READY and cycle on (the slaves' SM watchdogs stay fed) until the test
    writes a line."""
    print("READY", flush=True)
    while not select.select([sys.stdin], [], [], 0)[0]:
        exchange(master, hold)
    sys.stdin.readline()


def main() -> None:
    moving = [int(a) for a in sys.argv[2].split(",")]
    master = pysoem.Master()
    master.open(sys.argv[1])
    res: dict = {}
    try:
        res["found"] = master.config_init()
        res.update(identify(master))
        second = master.slaves[1]
        second.sdo_write(0x60F6 + 0x800, K43_SUB, struct.pack("<I", K43_VALUE))   # ID2's K43
        res.update(to_op(master))
        res["motion"] = enable_and_move(master, moving, 500)
        hold = [[(0x0F, t) for t in tg] for tg in res["motion"]["targets"]]
        wait_for_the_test(master, hold)                     # the second bridge is unplugged
        wkcs = [exchange(master, hold)[0] for _ in range(300)]
        master.read_state()
        res["unplugged"] = {
            "wkc_last": wkcs[-50:], "states": [s.state for s in master.slaves],
            "state_check": [s.state_check(pysoem.OP_STATE, 50_000) for s in master.slaves],
            "lowest": master.state_check(pysoem.OP_STATE, 50_000),
            "dl_status_1": struct.unpack("<H", master.slaves[0]._fprd(0x0110, 2))[0],
            "first_still_op": master.slaves[0].state}
        wait_for_the_test(master, hold)                     # plugged back
        res["again_found"] = master.config_init()
        res["again"] = identify(master)
        res["again"].update(to_op(master))
        res["again"]["motion"] = enable_and_move(master, moving, 100)
        master.state = pysoem.INIT_STATE
        master.write_state()
        res["init"] = master.state_check(pysoem.INIT_STATE, 500_000)
    finally:
        master.close()
    print(json.dumps(res))


if __name__ == "__main__":
    main()
