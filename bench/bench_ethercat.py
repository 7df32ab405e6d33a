"""Benchmark: the EtherCAT bridge's frame turnaround and late cycles against the 1 ms cycle.

A veth pair with the master's end in a network namespace (names ``cmecatb*``, always
removed).  The slave is ``coolmuscle sim --ethercat`` in-process (a Chain of 4 CM2
behind EB02, through :class:`EthercatTransport`); the master is SOEM (pysoem) in the
namespace under SCHED_FIFO, exchanging the 24+24-byte csp images (manual 6.3.1)
every 1 ms (6.3) with ID1's target position counting up.

Printed, side by side, for a run with no model behind the slave and a run with the
motor model behind it:

* the slave's frame turnaround (frame received to answer sent, in the frame thread):
  p50, p99, max, and p99 as a share of the 1 ms cycle;
* the master's round trip (send to receive) p50 / p99;
* late cycles: cycles whose answer missed the working counter or took longer than
  the 1 ms cycle, as a share of all cycles; and the bridge's own 1 ms model cycles
  that ran more than a cycle late.

Needs root.  ``--seconds`` sets each run's length (default 60)::

    sudo PYTHONPATH=src python bench/bench_ethercat.py [--seconds 60]

First, without root or a link (``--fmmu-only`` stops there), the cost of one LRD of
the 24-byte input image through the ESC alone, side by side: a byte-aligned FMMU of
24 bytes, a bit-wise one of 24 bytes and a bit-wise one of 65,535 bytes (the FMMUs are
decoded when configured: the work follows the bytes a datagram overlaps, not the
FMMU's length).
"""

from __future__ import annotations

import argparse
import json
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from coolmuscle.chain import Chain  # noqa: E402
from coolmuscle.frontends.ethercat.bridge.app import BridgeApp  # noqa: E402
from coolmuscle.frontends.ethercat.engine import esc as E  # noqa: E402
from coolmuscle.frontends.ethercat.lab import veth_pair  # noqa: E402
from coolmuscle.frontends.ethercat.transport import EthercatTransport, FrameThread  # noqa: E402
from coolmuscle.frontends.transports.service import ServiceThread  # noqa: E402

CYCLE = 0.001

MASTER = r"""
import json, struct, sys, time
import pysoem
m = pysoem.Master(); m.open(sys.argv[1]); m.config_init(); s = m.slaves[0]
m.config_map(); m.state_check(pysoem.SAFEOP_STATE, 500000)
m.state = pysoem.OP_STATE; m.write_state()
for _ in range(500):
    m.send_processdata(); m.receive_processdata(5000)
    if m.state_check(pysoem.OP_STATE, 5000) == pysoem.OP_STATE: break
seconds = float(sys.argv[2]); n = int(seconds / 0.001)
rtt = []; bad = 0; nxt = time.perf_counter()
for i in range(n):
    s.output = struct.pack("<Hi", 6, i) + bytes(18)
    t0 = time.perf_counter(); m.send_processdata(); w = m.receive_processdata(20000)
    dt = time.perf_counter() - t0; rtt.append(dt)
    if w != m.expected_wkc: bad += 1
    nxt += 0.001; d = nxt - time.perf_counter()
    if d > 0: time.sleep(d)
m.state = pysoem.INIT_STATE; m.write_state(); m.close()
print(json.dumps({"cycles": n, "bad_wkc": bad, "rtt": rtt}))
"""


def pct(values: list[float], p: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(p / 100 * len(ordered)))] if ordered else 0.0


def run_master(lab: Any, seconds: float) -> dict[str, Any]:
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
        f.write(MASTER)
    done = subprocess.run(["ip", "netns", "exec", lab.namespace, "chrt", "-f", "30",
                           sys.executable, f.name, lab.master_if, str(seconds)],
                          capture_output=True, text=True, timeout=seconds * 3 + 60)
    Path(f.name).unlink()
    if done.returncode:
        raise SystemExit(f"master failed: {done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def summarize(name: str, master: dict[str, Any], turnaround: list[int],
              model_late: int | None) -> dict[str, Any]:
    rtt = master["rtt"]
    late = sum(1 for r in rtt if r > CYCLE)
    return {"run": name, "cycles": master["cycles"],
            "turn_p50": pct(turnaround, 50) / 1000, "turn_p99": pct(turnaround, 99) / 1000,
            "turn_max": max(turnaround) / 1000 if turnaround else 0.0,
            "rtt_p50": pct(rtt, 50) * 1e6, "rtt_p99": pct(rtt, 99) * 1e6,
            "late_share": (late + master["bad_wkc"]) / master["cycles"],
            "bad_wkc": master["bad_wkc"], "model_late": model_late}


def bare(seconds: float) -> dict[str, Any]:
    app = BridgeApp(None)
    with veth_pair("cmecatb1", inside="master") as lab:
        frames = FrameThread(app.stack.esc, lab.slave_if)
        frames.start()
        try:
            master = run_master(lab, seconds)
        finally:
            frames.close()
    return summarize("slave only", master, list(frames.turnaround_ns), None)


def with_model(seconds: float) -> dict[str, Any]:
    with veth_pair("cmecatb2", inside="master") as lab:
        with ServiceThread(lambda: Chain(None, 4, firmware="cm2"),
                           lambda: [EthercatTransport(lab.slave_if, "EB02")]) as st:
            transport = st.transports[0]
            master = run_master(lab, seconds)
            turnaround = list(transport.frames.turnaround_ns)
            model_late = transport.late_cycles
    return summarize("motor model behind", master, turnaround, model_late)


def fmmu_lrd(length: int, bitwise: bool, rounds: int = 2000) -> float:
    """Microseconds per LRD of 24 bytes through one FMMU of ``length`` bytes (bit-wise:
    logical start bit 3, physical start bit 5), the ESC alone (no model)."""
    esc = BridgeApp(None).stack.esc
    lsb, psb = (3, 5) if bitwise else (0, 0)
    esc.write(E.REG_FMMU, struct.pack("<IHBBHBBB3x", 0x10000, length, lsb, 7, 0x1180, psb,
                                      1, 1))
    body = struct.pack("<BBIHH", E.LRD, 0, 0x10000, 24, 0) + bytes(24) + b"\0\0"
    frame = b"\xff" * 6 + b"\x01" * 6 + b"\x88\xa4" + struct.pack("<H", len(body) | 0x1000) \
        + body
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(rounds):
            esc.process(frame)
        best = min(best, (time.perf_counter() - t0) / rounds * 1e6)
    return best


def print_fmmu() -> None:
    rows = [("byte-aligned, 24 B", fmmu_lrd(24, False)), ("bit-wise, 24 B", fmmu_lrd(24, True)),
            ("bit-wise, 65,535 B", fmmu_lrd(65535, True))]
    base = rows[0][1]
    print("One LRD of 24 bytes through the ESC (best of 3), by the FMMU that maps it")
    for name, us in rows:
        print(f"  {name:<20} {us:>8.1f} us   {us / base:>5.2f}x the byte-aligned one")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="length of each run")
    parser.add_argument("--fmmu-only", action="store_true",
                        help="only the FMMU rows (no root, no link)")
    args = parser.parse_args()
    print_fmmu()
    if args.fmmu_only:
        return
    started = time.time()
    rows = [bare(args.seconds), with_model(args.seconds)]
    print(f"EtherCAT bridge, SOEM master, 1 ms cycle ({CYCLE * 1e6:.0f} us), "
          f"{args.seconds:g} s a run")
    print(f"{'run':<20} {'cycles':>7} {'turn p50':>9} {'turn p99':>9} {'p99/cycle':>9} "
          f"{'turn max':>9} {'rtt p50':>8} {'rtt p99':>8} {'late':>8} {'model late':>10}")
    for r in rows:
        print(f"{r['run']:<20} {r['cycles']:>7} {r['turn_p50']:>7.1f}us {r['turn_p99']:>7.1f}us "
              f"{r['turn_p99'] / (CYCLE * 1e6):>9.3f} {r['turn_max']:>7.0f}us "
              f"{r['rtt_p50']:>6.0f}us {r['rtt_p99']:>6.0f}us {r['late_share']:>8.4%} "
              f"{'-' if r['model_late'] is None else r['model_late']:>10}")
    a, b = rows
    if a["turn_p99"]:
        print(f"turnaround p99 with the model / without: {b['turn_p99'] / a['turn_p99']:.2f}; "
              f"late share with / without: {b['late_share']:.4%} / {a['late_share']:.4%}")
    load = open('/proc/loadavg').read().split()[0]
    print(f"({time.time() - started:.0f} s; load average {load})")


if __name__ == "__main__":
    main()
