"""A real EtherCAT master (SOEM through pysoem) run against the bridge: prints JSON.

Run inside the test's network namespace: ``python soem_master.py IFACE SCENARIO``.
Scenarios: ``full`` (scan, SDO, map, SAFE-OP, OP, cycles, INIT), ``invalid`` (INIT to
OP refused with 0011h), ``watchdog`` (the master stops sending in OP), ``csp``, ``fault``,
``wire`` (every kind of SDO transfer, SDO information, csp cycles: the capture test),
``misconfigure`` (SM1 pointed at the registers in PRE-OP).
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
    return {"cycles": n, "wkc_ok": ok, "missed": missed, "master_late": late,
            "last_input": last_in.hex()}


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


def misconfigure(master) -> dict:
    """A careless master in PRE-OP: SM1 (the read mailbox) rewritten in place at AL status
    (0x0130), then deactivated, pointed there and activated again, an SDO request between
    each; what the slave's AL status, code and SM1 registers read after each step."""
    master.config_init()
    s = master.slaves[0]
    res = {"preop": s.state_check(pysoem.PREOP_STATE, 500_000)}

    def al() -> list[int]:
        return list(struct.unpack("<HxxH", s._fprd(0x0130, 6)))

    def sdo() -> str:
        try:
            return s.sdo_read(0x1018, 1).hex()
        except Exception as exc:               # the mailbox is down: SOEM gives up
            return type(exc).__name__
    bad = struct.pack("<HHBBBB", 0x0130, 128, 0x22, 0, 1, 0)
    s._fpwr(0x0808, bad)                              # in place, still activated
    res["in_place_sm1"] = s._fprd(0x0808, 8).hex()
    res["in_place_sdo"] = sdo()
    res["in_place_al"] = al()
    s._fpwr(0x080E, b"\x00")                          # deactivated
    res["deactivated_al"] = al()
    s._fpwr(0x0808, bad)                              # pointed at the registers, activated
    res["pointed_sm1"] = s._fprd(0x0808, 8).hex()
    res["pointed_sdo"] = sdo()
    res["pointed_al"] = al()
    return res


def csp(master) -> dict:
    """6.1.2: 0x06, 0x07, 0x0F on every axis, then a 2 s csp ramp of 4,000 pulses."""
    master.config_init()
    s = master.slaves[0]
    res = to_op(master, s)

    def exchange(cw: int, targets: list[int]) -> list[tuple[int, int]]:
        s.output = b"".join(struct.pack("<Hi", cw, t) for t in targets)
        master.send_processdata()
        master.receive_processdata(10_000)
        time.sleep(0.001)
        return [struct.unpack_from("<Hi", s.input, 6 * a) for a in range(4)]
    now = exchange(0, [0] * 4)
    start = [p for _w, p in now]
    words = {}
    for cw in (0x06, 0x07, 0x0F):
        for _ in range(30):
            now = exchange(cw, start)
        words[hex(cw)] = [w for w, _p in now]
    lag = 0
    for i in range(2000):
        targets = [p + 4000 * (i + 1) // 2000 for p in start]
        now = exchange(0x0F, targets)
        lag = max(lag, max(abs(t - p) for t, (_w, p) in zip(targets, now)))
    for _ in range(500):
        now = exchange(0x0F, targets)
    res.update(words=words, start=start, final=[p for _w, p in now],
               final_words=[w for w, _p in now], targets=targets, max_lag=lag)
    for _ in range(30):
        now = exchange(0x06, targets)
    res["after_shutdown"] = [w for w, _p in now]
    return res


def fault(master) -> dict:
    """Operation enabled, then the test injects an alarm on ID2: Fault, fault reset."""
    master.config_init()
    s = master.slaves[0]
    res = to_op(master, s)

    def exchange(cws: list[int], targets: list[int]) -> list[tuple[int, int]]:
        s.output = b"".join(struct.pack("<Hi", c, t) for c, t in zip(cws, targets))
        master.send_processdata()
        master.receive_processdata(10_000)
        time.sleep(0.001)
        return [struct.unpack_from("<Hi", s.input, 6 * a) for a in range(4)]
    now = exchange([0] * 4, [0] * 4)
    start = [p for _w, p in now]
    for cw in (0x06, 0x07, 0x0F):
        for _ in range(30):
            now = exchange([cw] * 4, start)
    res["enabled"] = [w for w, _p in now]
    print("READY", flush=True)
    sys.stdin.readline()                          # the test injects the alarm now
    for _ in range(100):
        now = exchange([0x0F] * 4, start)
    res["faulted"] = [w for w, _p in now]
    for cw in (0x80, 0x06, 0x07, 0x0F):
        for _ in range(30):
            now = exchange([cw] * 4, start)
        res[f"after_{cw:#04x}"] = [w for w, _p in now]
    return res


def wire(master) -> dict:
    """Every kind of mailbox exchange, then csp cycles, for the capture test
    (test_wireshark.py): what was sent and what came back, in order."""
    master.config_init()
    s = master.slaves[0]
    ups = [(0x1000, 0), (0x1008, 0), (0x1018, 1), (0x1018, 2), (0x1018, 3), (0x1018, 4)]
    res: dict = {"uploads": [[i, k, s.sdo_read(i, k).hex()] for i, k in ups]}
    s.sdo_write(0x6060, 0, struct.pack("<b", 8))                       # expedited download
    s.sdo_write(0x6099, 1, struct.pack("<I", 2000))
    res["downloads"] = [[0x6060, 0, "08"], [0x6099, 1, struct.pack("<I", 2000).hex()]]
    res["abort"] = [0x2000, 0, abort_of(s, 0x2000, 0)]
    k = s.sdo_read(0x60F6, 1, 1024, ca=True)                            # segmented upload
    s.sdo_write(0x60F6, 1, k, ca=True)                                  # segmented download
    res["segmented"] = [0x60F6, 1, k.hex()]
    od = s.od                                                           # SDO information
    res["od"] = [o.index for o in od]
    described = [o for o in od if o.index in (0x1018, 0x6040, 0x60F6)]
    res["names"] = [[o.index, o.name.decode("latin-1")] for o in described]
    res["entries"] = [[e.name.decode("latin-1"), e.data_type, e.bit_length]
                      for e in described[0].entries]
    res.update(to_op(master, s))
    sent, seen = [], []
    for i in range(300):                  # 6.1.2: 06h, 07h, 0Fh; then a csp ramp on ID1
        cw = 0x06 if i < 30 else 0x07 if i < 60 else 0x0F
        target = 10 * max(0, i - 90)
        s.output = b"".join(struct.pack("<Hi", cw, target if a == 0 else 0) for a in range(4))
        master.send_processdata()
        master.receive_processdata(10_000)
        sent.append(bytes(s.output).hex())
        seen.append(bytes(s.input).hex())
        time.sleep(0.001)
    res.update(sent=sent, seen=seen)
    master.state = pysoem.INIT_STATE
    master.write_state()
    res["init"] = master.state_check(pysoem.INIT_STATE, 500_000)
    return res


def main() -> None:
    master = pysoem.Master()
    master.open(sys.argv[1])
    try:
        result = {"full": full, "invalid": invalid, "watchdog": watchdog,
                  "csp": csp, "fault": fault, "wire": wire,
                  "misconfigure": misconfigure}[sys.argv[2]](master)
    finally:
        master.close()
    print(json.dumps(result))


if __name__ == "__main__":
    main()
