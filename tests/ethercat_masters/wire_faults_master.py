"""SOEM (pysoem) as the master of two bridges while the test breaks the wire: prints JSON.

``python wire_faults_master.py IFACE``: scan, map, OP, then phases.  Before each phase
the master prints ``READY`` and waits for a line on stdin naming it (the test installs
the fault in the model first), runs it and records what SOEM reports:

* ``wkc``: 200 process-data cycles, every working counter ``receive_processdata``
  returns;
* ``lost``: 100 cycles, the same;
* ``mailbox``: an SDO upload of 1008h from the first bridge (its answer is lost once);
* ``link``: cycles for 1.5 s while the second bridge's link goes down and comes back,
  then each slave's AL status and AL status code as SOEM reads them, the acknowledge
  (SAFE-OP + ACK) and OP again, and 100 cycles.

``done`` ends it: INIT, and the JSON on the last line.
"""

from __future__ import annotations

import json
import sys
import time

import pysoem


def cycle(master, n: int) -> list[int]:
    wkcs = []
    for _ in range(n):
        master.send_processdata()
        wkcs.append(master.receive_processdata(10_000))
        time.sleep(0.001)
    return wkcs


def to_op(master) -> int:
    master.config_map()
    master.state_check(pysoem.SAFEOP_STATE, 500_000)
    return request_op(master)


def request_op(master) -> int:
    """Ask for OP and run cycles until every slave is there (300 at most)."""
    master.state = pysoem.OP_STATE
    master.write_state()
    for _ in range(300):
        cycle(master, 1)
        if master.state_check(pysoem.OP_STATE, 5000) == pysoem.OP_STATE:
            break
    return master.state_check(pysoem.OP_STATE, 5000)


def states(master) -> list[list[int]]:
    master.read_state()
    return [[s.state, s.al_status] for s in master.slaves]


def link_phase(master) -> dict:
    start = time.monotonic()
    wkcs: list[int] = []
    while time.monotonic() - start < 1.5:
        wkcs += cycle(master, 10)
    out = {"wkcs": wkcs, "after": states(master)}
    for s in master.slaves:                       # SOEM's recovery: acknowledge, then OP
        if s.state & pysoem.STATE_ERROR:
            s.state = pysoem.SAFEOP_STATE | pysoem.STATE_ACK
            s.write_state()
    cycle(master, 20)
    request_op(master)
    out["recovered"] = states(master)
    out["wkcs_again"] = cycle(master, 100)
    return out


def main() -> None:
    master = pysoem.Master()
    master.open(sys.argv[1])
    res: dict = {}
    try:
        res["found"] = master.config_init()
        res["names"] = [s.name for s in master.slaves]
        res["op"] = to_op(master)
        res["expected_wkc"] = master.expected_wkc
        res["clean"] = cycle(master, 200)
        while True:
            print("READY", flush=True)
            phase = sys.stdin.readline().strip()
            if phase in ("done", ""):
                break
            if phase == "wkc":
                res["wkc"] = cycle(master, 200)
            elif phase == "lost":
                res["lost"] = cycle(master, 100)
            elif phase == "mailbox":
                started = time.monotonic()
                try:
                    res["mailbox"] = {"name": master.slaves[0].sdo_read(0x1008, 0)
                                      .decode("latin-1")}
                except Exception as exc:        # what pysoem reports, for the test to see
                    res["mailbox"] = {"error": f"{type(exc).__name__}: {exc}"}
                res["mailbox"]["s"] = time.monotonic() - started
                res["mailbox"]["wkcs"] = cycle(master, 20)
            elif phase == "link":
                res["link"] = link_phase(master)
        master.state = pysoem.INIT_STATE
        master.write_state()
        res["init"] = master.state_check(pysoem.INIT_STATE, 500_000)
    finally:
        master.close()
    print(json.dumps(res))


if __name__ == "__main__":
    main()
