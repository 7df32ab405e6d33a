"""A real EtherCAT master (SOEM through pysoem) run against the bridge: prints JSON.

Run inside the test's network namespace: ``python soem_master.py IFACE SCENARIO``.
Scenarios: ``full`` (scan, SDO, map, SAFE-OP, OP, cycles, INIT), ``invalid`` (INIT to
OP refused with 0011h), ``watchdog`` (the master stops sending in OP).
"""

from __future__ import annotations

import json
import struct
import sys
import time

import pysoem


def abort_of(slave, index: int, sub: int, data: bytes | None = None) -> int:
    try:
        if data is None:
            slave.sdo_read(index, sub)
        else:
            slave.sdo_write(index, sub, data)
    except pysoem.SdoError as exc:
        return exc.abort_code
    return 0


def to_op(master, slave) -> dict:
    out = {"iomap": master.config_map(), "out_len": len(slave.output),
           "in_len": len(slave.input)}
    out["safeop"] = master.state_check(pysoem.SAFEOP_STATE, 500_000)
    master.state = pysoem.OP_STATE
    master.write_state()
    state = 0
    for _ in range(200):
        master.send_processdata()
        master.receive_processdata(5000)
        state = master.state_check(pysoem.OP_STATE, 5000)
        if state == pysoem.OP_STATE:
            break
    out["op"] = state
    out["expected_wkc"] = master.expected_wkc
    return out


def cycles(master, slave, n: int, period: float = 0.001) -> dict:
    ok = 0
    late = 0
    t_next = time.perf_counter()
    last_in = b""
    missed: list[int] = []
    for i in range(n):
        slave.output = struct.pack("<Hi", 0x0006, i) + bytes(18)
        master.send_processdata()
        wkc = master.receive_processdata(10_000)
        if wkc == master.expected_wkc:
            ok += 1
        elif len(missed) < 100:
            missed.append(i)
        last_in = bytes(slave.input)
        t_next += period
        delay = t_next - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        else:
            late += 1
    return {"cycles": n, "wkc_ok": ok, "missed": missed, "master_late": late, "last_input": last_in.hex()}


def full(master) -> dict:
    found = master.config_init()
    s = master.slaves[0]
    res = {"found": found, "name": s.name, "vendor": s.man, "product": s.id, "revision": s.rev,
           "sdo_1000": s.sdo_read(0x1000, 0).hex(),
           "sdo_1008": s.sdo_read(0x1008, 0).decode("latin-1"),
           "sdo_1018": [struct.unpack("<I", s.sdo_read(0x1018, k))[0] for k in range(1, 5)],
           "sdo_1018_0": s.sdo_read(0x1018, 0)[0],
           "abort_absent": abort_of(s, 0x2000, 0),
           "abort_read_only": abort_of(s, 0x1018, 1, b"\x00\x00\x00\x00"),
           "abort_subindex": abort_of(s, 0x1018, 9)}
    od = s.od
    res["od_count"] = len(od)
    def text(x) -> str:
        return x.decode("latin-1") if isinstance(x, bytes) else str(x)
    res["od_1018"] = [(text(o.name), [text(e.name) for e in o.entries])
                      for o in od if o.index == 0x1018]
    res.update(to_op(master, s))
    res.update(cycles(master, s, int(sys.argv[3]) if len(sys.argv) > 3 else 10_000))
    master.state = pysoem.INIT_STATE
    master.write_state()
    res["init"] = master.state_check(pysoem.INIT_STATE, 500_000)
    return res


def invalid(master) -> dict:
    master.config_init()
    s = master.slaves[0]
    s.state = pysoem.INIT_STATE
    s.write_state()
    res = {"init": s.state_check(pysoem.INIT_STATE, 500_000)}
    s.state = pysoem.OP_STATE
    s.write_state()
    time.sleep(0.05)
    master.read_state()
    res["after_op_request"] = s.state
    res["al_status_code"] = s.al_status
    s.state = pysoem.INIT_STATE | 0x10          # acknowledge
    s.write_state()
    time.sleep(0.05)
    master.read_state()
    res["after_ack"] = s.state
    res["code_after_ack"] = s.al_status
    return res


def watchdog(master) -> dict:
    master.config_init()
    s = master.slaves[0]
    res = to_op(master, s)
    res.update(cycles(master, s, 100))
    time.sleep(0.5)                               # the master stops sending
    master.read_state()
    res["after_silence"] = s.state
    res["al_status_code"] = s.al_status
    return res


def main() -> None:
    master = pysoem.Master()
    master.open(sys.argv[1])
    try:
        result = {"full": full, "invalid": invalid, "watchdog": watchdog}[sys.argv[2]](master)
    finally:
        master.close()
    print(json.dumps(result))


if __name__ == "__main__":
    main()
