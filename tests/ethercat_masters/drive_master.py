"""SOEM (pysoem) drives the bridge's four axes like a PLC would: prints JSON results.

Run inside the test's network namespace: ``python drive_master.py IFACE``.  Steps
(ethercat-bridge-users-guide.txt): 6.1.2 controlwords 06h/07h/0Fh on every axis; a
2 s csp ramp of 4,000 pulses on all four (6.3); homing of ID1 by 6098h (Appendix 4);
CMD mode F307h on ID3 (Appendix 1.1); CPIO outputs on ID4 (7.1); then it prints
``STEP fault`` and waits for the test to inject a motor alarm on ID2, shows it as
Fault and clears it with a fault reset (6.1.1).
"""

from __future__ import annotations

import json
import struct
import sys
import time

import pysoem

OFF = 0x800


class Io:
    """The 24-byte csp images (6.3.1) of four axes, cycled at 1 ms."""

    def __init__(self, master, slave) -> None:
        self.m, self.s = master, slave
        self.cw = [0] * 4
        self.target = [0] * 4
        self.sw = [0] * 4
        self.pos = [0] * 4
        self.wkc_bad = 0
        self._next = time.perf_counter()

    def run(self, n: int = 1) -> None:
        for _ in range(n):
            self.s.output = b"".join(struct.pack("<Hi", c & 0xFFFF, t)
                                     for c, t in zip(self.cw, self.target))
            self.m.send_processdata()
            if self.m.receive_processdata(10_000) != self.m.expected_wkc:
                self.wkc_bad += 1
            data = bytes(self.s.input)
            for a in range(4):
                self.sw[a], self.pos[a] = struct.unpack_from("<Hi", data, 6 * a)
            self._next += 0.001
            delay = self._next - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            else:
                self._next = time.perf_counter()

    def until(self, predicate, limit: int) -> int:
        for i in range(limit):
            if predicate():
                return i
            self.run(1)
        return -1

    def sdo_write(self, index: int, sub: int, fmt: str, value: int) -> None:
        self.s.sdo_write(index, sub, struct.pack("<" + fmt, value))
        self.run(2)

    def sdo_read(self, index: int, sub: int, fmt: str) -> int:
        value = struct.unpack("<" + fmt, self.s.sdo_read(index, sub)[:struct.calcsize(fmt)])[0]
        self.run(2)
        return value

    def switch_mode(self, axis: int, mode: int) -> int:
        """Appendix 3: 6060h, then 6061h every 5 ms until it shows (ms waited or -1).
        A refusal (08000022h: not in position yet) is retried every 10 ms."""
        for _ in range(50):
            try:
                self.sdo_write(0x6060 + OFF * axis, 0, "b", mode)
                break
            except pysoem.SdoError:
                self.run(10)
        for waited in range(0, 200, 5):
            if self.sdo_read(0x6061 + OFF * axis, 0, "b") == mode:
                return waited
            self.run(5)
        return -1


def cml(io: Io) -> dict:
    """Appendix 3.3 + 3.2 (hm -> csp -> CML), then Appendix 2.3 and 2.5 on ID1."""
    io.target[0] = io.pos[0]              # 3.3: "actual position follows target position"
    out = {"csp_again": io.switch_mode(0, 8)}
    io.run(20)
    out["cml_switch"] = io.switch_mode(0, 101)
    io.cw[0] = 0x0000                                               # "Set 0000h"
    io.run(5)

    def poll(limit: int, every: int) -> list[str]:
        lines: list[str] = []
        for _ in range(limit):
            line = io.s.sdo_read(0xF591, 0).decode("latin-1")
            if line != "Null\r\n":
                lines.append(line)
            elif lines:
                break
            io.run(every)
        return lines

    drained = 0                           # earlier reports (Ux, Origin): Appendix 2.1 "another
    while io.s.sdo_read(0xF591, 0) != b"Null\r\n" and drained < 5000:   # data received"
        drained += 1
        io.run(1)                         # process data goes on (the SM watchdog)
    out["drained"] = drained
    io.s.sdo_write(0xF581, 0, b"?99.1")
    out["q99"] = poll(50, 2)
    io.s.sdo_write(0xF581, 0, b"?90.1")
    io.run(3)
    out["q90"] = poll(100, 10)
    try:
        io.s.sdo_write(0xF581, 0, b"?99.1," * 11)                  # 66 bytes
        out["too_long"] = 0
    except pysoem.SdoError as exc:
        out["too_long"] = exc.abort_code
    return out


def to_op(master, slave) -> int:
    master.config_map()
    master.state_check(pysoem.SAFEOP_STATE, 500_000)
    master.state = pysoem.OP_STATE
    master.write_state()
    for _ in range(300):
        master.send_processdata()
        master.receive_processdata(5000)
        if master.state_check(pysoem.OP_STATE, 5000) == pysoem.OP_STATE:
            return pysoem.OP_STATE
    return master.state_check(pysoem.OP_STATE, 5000)


def scenario(master) -> dict:
    master.config_init()
    s = master.slaves[0]
    res: dict = {"op": to_op(master, s)}
    io = Io(master, s)
    io.run(20)
    res["sw_start"] = list(io.sw)
    io.target = list(io.pos)
    for cw in (0x06, 0x07, 0x0F):                                   # 6.1.2
        io.cw = [cw] * 4
        io.run(10)
        res[f"sw_{cw:02x}"] = list(io.sw)
    start = list(io.pos)                                            # 6.3: 2 s, 4,000 pulses
    lag = [0] * 4
    lag3 = [0] * 4                     # against the target of 3 cycles ago (the pipeline)
    for i in range(1, 2001):
        io.target = [p + 2 * i for p in start]
        io.run(1)
        lag = [max(lag[a], io.target[a] - io.pos[a]) for a in range(4)]
        lag3 = [max(lag3[a], io.target[a] - 6 - io.pos[a]) for a in range(4)]
    io.run(300)
    io.until(lambda: all(abs(io.pos[a] - io.target[a]) <= 10 for a in range(4)), 2000)
    master.read_state()
    res.update(ramp_start=start, ramp_end=list(io.pos), max_lag=lag, max_lag3=lag3,
               ramp_sw=list(io.sw), al_after_ramp=s.state, al_code=s.al_status)
    res["hm_switch"] = io.switch_mode(0, 6)                         # Appendix 4, ID1
    io.sdo_write(0x6098, 0, "B", 2)                                 # stopper CCW
    io.sdo_write(0x6099, 2, "I", 60)
    io.run(100)
    io.cw[0] = 0x1F
    res["hm_running"] = io.until(lambda: io.sw[0] & 0x3400 == 0, 500)   # bit 10 drops
    res["hm_cycles"] = io.until(lambda: io.sw[0] & 0x3000, 20_000)
    res["hm_sw"] = io.sw[0]
    io.cw[0] = 0x0F
    io.run(20)
    res["hm_pos"] = io.pos[0]
    io.sdo_write(0x70F6, 0x16, "I", 100)                            # ID3 K42 = 100 (7.5)
    res["k42_3"] = io.sdo_read(0x70F6, 0x16, "I")
    res["cmd_switch"] = io.switch_mode(2, 120)                      # Appendix 1.1, ID3
    io.cw[2] = 0x0007
    io.run(5)
    io.cw[2] = 0xF307
    io.run(5)
    res["cmd_ack"] = io.sw[2] >> 8
    res["cmd_cycles"] = io.until(lambda: io.sw[2] >> 8 in (0xF8, 0xF9), 20_000)
    res["cmd_done"] = io.sw[2] >> 8
    io.cw[2] = 0x0007
    io.run(5)
    io.sdo_write(0x78F6, 0x0E, "I", 3333)                           # ID4 K34: general use
    res["cpio_switch"] = io.switch_mode(3, 121)                     # 7.1, ID4
    io.cw[3] = 0xC03F                                               # OUT1 + OUT2, enabled
    io.run(20)
    res["cpio_sw"] = io.sw[3]
    res["f530_tx"] = io.sdo_read(0xF530, 0x09, "I")
    res.update(cml(io))                                              # Appendix 2, ID1
    print("STEP fault", flush=True)                                 # the test injects it
    res["fault_cycles"] = io.until(lambda: io.sw[1] & 0x4F == 0x08, 5000)
    res["fault_sw"] = io.sw[1]
    io.cw[1] = 0x80                                                 # 15: fault reset
    io.until(lambda: io.sw[1] & 0x4F != 0x08, 1000)
    res["reset_sw"] = io.sw[1]
    io.target[1] = io.pos[1]
    for cw, bits in ((0x06, 0x21), (0x07, 0x23), (0x0F, 0x27)):
        io.cw[1] = cw
        io.until(lambda b=bits: io.sw[1] & 0x6F == b, 1000)
        io.run(5)
    res["reenabled_sw"] = io.sw[1]
    res["wkc_bad"] = io.wkc_bad
    master.state = pysoem.INIT_STATE
    master.write_state()
    res["init"] = master.state_check(pysoem.INIT_STATE, 500_000)
    return res


def main() -> None:
    master = pysoem.Master()
    master.open(sys.argv[1])
    try:
        result = scenario(master)
    finally:
        master.close()
    print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
