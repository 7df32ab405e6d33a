"""Benchmark: an EtherCAT wire-fault storm for minutes, sans IO (docs/wire-faults.md).

Three bridges in a line (EB02, EB12, EB01; their chains on one kernel, as ``sim
--ethercat --bridges`` runs them) under a small master in virtual time: one LRW a
millisecond (6.3), an SDO upload through the first bridge's mailbox every 50 ms (with
SM1's repeat request when its answer is lost), and a rain of ``ethercat`` faults of
every kind (lost frames out and back, working counters off, lost mailbox answers, the
link into the third bridge down for 150 ms, late cycles), installed and over again and
again; after each link down the master acknowledges and takes the bridges to OP again.
No network and no wall clock in the model: the frames are bytes handed to the segment
(the engine is sans IO), so the run is the same every time.

Printed: the resident memory at the start and at each sample, the frames, what the
faults did (lost, counters changed, cycles skipped), the SDOs completed and the repeats
they needed, the recoveries to OP, and the counts that must stay 0 (an exception, an
SDO that never completed, a bridge not back in OP).

::

    PYTHONPATH=src python bench/bench_ethercat_wirefaults.py [--minutes 10] [--samples 10]
"""

from __future__ import annotations

import argparse
import resource
import struct
import sys
import time

from coolmuscle.chain import Chain
from coolmuscle.frontends.ethercat.bridge import identity as ident
from coolmuscle.frontends.ethercat.bridge.segment import BridgeSegment
from coolmuscle.frontends.ethercat.engine import esc as E
from coolmuscle.frontends.ethercat.engine import esm
from coolmuscle.sim.kernel import Kernel

MS = 1_000_000
CODES = ("EB02", "EB12", "EB01")
HEAD = b"\xff" * 6 + b"\x01" * 6 + b"\x88\xa4"


def frame(cmd: int, adp: int, ado: int, data: bytes) -> bytes:
    body = struct.pack("<BBHHHH", cmd, 0, adp, ado, len(data), 0) + data + b"\0\0"
    return HEAD + struct.pack("<H", len(body) | 0x1000) + body


def rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


class Storm:
    def __init__(self) -> None:
        self.kernel = Kernel()
        self.chains = [Chain(self.kernel, 4, firmware=",".join(ident.variant(c).firmware))
                       for c in CODES]
        self.seg = BridgeSegment(self.chains, CODES)
        self.seg.start_cycles()
        self.frames = self.sdos = self.repeats = self.recoveries = 0
        self.failures: list[str] = []

    def send(self, cmd: int, adp: int, ado: int, data: bytes) -> tuple[bytes, int] | None:
        self.frames += 1
        out = self.seg.line.process(frame(cmd, adp, ado, data), self.kernel.now)
        if out is None:
            return None
        n = len(data)
        return bytes(out[26:26 + n]), out[26 + n] | out[27 + n] << 8

    def write(self, station: int, ado: int, data: bytes) -> None:
        for _ in range(10):                       # a lost frame is sent again
            got = self.send(E.FPWR, station, ado, data)
            if got is not None:
                return

    def to_op(self) -> None:
        for n in range(len(CODES)):
            station = 0x1001 + n
            self.send(E.APWR, -n & 0xFFFF, E.REG_STATION, struct.pack("<H", station))
            self.write(station, E.REG_AL_CONTROL, struct.pack("<H", esm.INIT | esm.ACK))
            self.write(station, E.REG_WD_DIVIDER, struct.pack("<H", 2498))
            self.write(station, E.REG_WD_SM, struct.pack("<H", 1000))
            for s, (start, size, ctl) in enumerate(((ident.MBX_OUT_START, 128, 0x26),
                                                    (ident.MBX_IN_START, 128, 0x22),
                                                    (ident.PD_OUT_START, 24, 0x64),
                                                    (ident.PD_IN_START, 24, 0x20))):
                self.write(station, E.REG_SM + 8 * s,
                           struct.pack("<HHBBBB", start, size, ctl, 0, 1, 0))
            for f, (logical, phys, kind) in enumerate(((24 * n, ident.PD_OUT_START, 2),
                                                       (72 + 24 * n, ident.PD_IN_START, 1))):
                self.write(station, E.REG_FMMU + 16 * f,
                           struct.pack("<IHBBHBBB3x", logical, 24, 0, 7, phys, 0, kind, 1))
        for state in (esm.PREOP, esm.SAFEOP, esm.OP):
            for n in range(len(CODES)):
                self.write(0x1001 + n, E.REG_AL_CONTROL, struct.pack("<H", state))
            self.cycle()

    def cycle(self) -> None:
        self.send(E.LRW, 0, 0, bytes(144))
        self.kernel.run(until=self.kernel.now + MS)

    def sdo(self, counter: int) -> None:
        """An SDO upload of 1000h from the first bridge, as SOEM reads a mailbox."""
        body = struct.pack("<HBHB", 0x2000, 0x40, 0x1000, 0) + bytes(4)
        mbx = (struct.pack("<HHBB", len(body), 0, 0, 0x03 | counter << 4) + body)
        self.write(0x1001, ident.MBX_OUT_START, mbx.ljust(128, b"\0"))
        for _ in range(20):
            status = self.send(E.FPRD, 0x1001, E.REG_SM + 8 + 5, bytes(2))
            if status is None or not status[0][0] & 0x08:
                self.cycle()
                continue
            answer = self.send(E.FPRD, 0x1001, ident.MBX_IN_START, bytes(128))
            if answer is not None and answer[1] == 1:
                self.sdos += 1
                return
            self.repeats += 1                      # lost: toggle the repeat request
            self.write(0x1001, E.REG_SM + 8 + 6, bytes([status[0][1] ^ 0x02]))
        self.failures.append(f"SDO {counter} never completed at {self.kernel.now} ns")

    def rain(self, i: int) -> None:
        device = self.chains[0]
        if i % 100 == 0:
            device.inject_wire_fault("ethercat", "lost_frame", probability=0.02, seed=i,
                                     until=0.05)
            device.inject_wire_fault("ethercat", "lost_frame", way="back", every=17, count=2)
            device.inject_wire_fault("ethercat", "wkc", probability=0.1, seed=i + 1,
                                     until=0.08)
            device.inject_wire_fault("ethercat", "mailbox_lost", count=1)
            device.inject_wire_fault("ethercat", "late_cycle", ms=2.5, count=1)
        if i % 2000 == 0:
            device.inject_wire_fault("ethercat", "link_down", bridge=3, at=0.2, until=0.35)
        if i % 2000 == 1000:                       # long after the link came back
            states = [app.stack.esc.al_status for app in self.seg.apps]
            if states != [esm.OP] * 3:
                for n, state in enumerate(states):
                    if state & esm.ERROR_FLAG:
                        self.write(0x1001 + n, E.REG_AL_CONTROL,
                                   struct.pack("<H", esm.SAFEOP | esm.ACK))
                self.cycle()
                for n in range(3):
                    self.write(0x1001 + n, E.REG_AL_CONTROL, struct.pack("<H", esm.OP))
                self.cycle()
                self.recoveries += 1
            if [app.stack.esc.al_status for app in self.seg.apps] != [esm.OP] * 3:
                self.failures.append(f"not back in OP at {self.kernel.now} ns")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--samples", type=int, default=10)
    options = parser.parse_args()
    seconds = options.minutes * 60
    storm = Storm()
    storm.to_op()
    start_rss = rss_mib()
    print(f"ethercat wire-fault storm, {options.minutes:g} min wall, RSS {start_rss:.1f} MiB",
          flush=True)
    started = time.monotonic()
    next_sample = seconds / options.samples
    samples: list[float] = []
    i = 0
    try:
        while time.monotonic() - started < seconds:
            storm.rain(i)
            storm.cycle()
            if i % 50 == 25:
                storm.sdo(1 + i // 50 % 7)
            i += 1
            if time.monotonic() - started >= next_sample:
                samples.append(rss_mib())
                print(f"  {time.monotonic() - started:7.0f} s  {i:8d} cycles  "
                      f"RSS {samples[-1]:6.1f} MiB", flush=True)
                next_sample += seconds / options.samples
    except Exception as exc:                        # the count that must stay 0
        storm.failures.append(f"{type(exc).__name__}: {exc}")
    faults = storm.seg.faults
    assert faults is not None
    print(f"cycles {i}, frames {storm.frames}; lost {faults.lost}, counters changed "
          f"{faults.changed}, cycles skipped {faults.skipped}; SDOs {storm.sdos} "
          f"({storm.repeats} repeats); recoveries to OP {storm.recoveries}")
    if samples:
        middle, end = samples[len(samples) // 2], samples[-1]
        print(f"RSS start {start_rss:.1f} MiB, middle {middle:.1f} MiB, end {end:.1f} MiB "
              f"(end - middle {end - middle:+.1f} MiB)")
    print(f"faults still installed {len(storm.chains[0].wire_faults.faults)}")
    for line in storm.failures[:5]:
        print("  !", line)
    print("clean" if not storm.failures else f"NOT CLEAN ({len(storm.failures)})")
    sys.exit(0 if not storm.failures else 1)


if __name__ == "__main__":
    main()
