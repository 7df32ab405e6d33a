"""Benchmark: the 4-axis bridge in csp at 1 ms (ethercat-bridge-users-guide.txt 6.3).

The bridge application (:class:`BridgeApp`, part 2's drive behind it) with a Chain of
four CM2 in one thread, paced to the wall clock like ``sim --ethercat``: the bridge
cycle is a kernel event every 1 ms of virtual time (``BridgeApp.start_cycles``, the
CM port's own cycle); every wall millisecond the RxPDO image of that millisecond
arrives (all four axes in Operation enabled, each following a triangle of +/-4,000
pulses at 2 pulses/ms, a new target every cycle) and the kernel runs to the
wall-clock instant.  No network: this is the model's side of the 1 ms cycle, the
part that decides whether four axes keep up.

Printed side by side, for the axes following (csp moving) and holding (same target):

* missed cycles: cycles that started more than one cycle after they were due (they
  still run, back to back, as in the transport: virtual time does not skip them);
* CPU share: process CPU time over wall time (the spin before each cycle included);
* the cost of one axis-cycle (CPU time of a bridge cycle with its kernel run, / 4)
  against the 50 us goal (docs/performance.md), and the 1 ms cycle it must fit in;
* what a late cycle was late by (p99, worst) and the CPU time the machine's hypervisor
  took from this virtual machine meanwhile (steal, /proc/stat);
* the same for an empty cycle: the same wait for each slot at the same priority with
  nothing to do, the cycles the machine itself starts late (its stalls, the steal), the
  floor under the bridge's count; and how far above that floor each bridge run is.

The loop runs as ``sim --ethercat`` runs the model's thread where the system allows it
(root, CAP_SYS_NICE): under SCHED_FIFO at the transport's priority.  It waits for a
cycle by sleeping until ``--spin-us`` before it and spinning the rest (a sleeping
virtual CPU wakes 0.1-1 ms late); and the cyclic collector is set as ``sim --ethercat``
sets it (``transport.cycle_collector``: what ships is measured).  The collections that
start during each run are counted by generation with the longest one
(``gc.callbacks``).  ``--collector between`` runs the collector between cycles instead
(automatic collection off, a collection when the next cycle is at least ``GC_SLACK``
away), for comparison.

    PYTHONPATH=src python bench/bench_ethercat_csp.py [--seconds 60] [--collector between]
"""

from __future__ import annotations

import argparse
import gc
import os
import struct
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from coolmuscle.chain import Chain  # noqa: E402
from coolmuscle.frontends.ethercat.bridge.app import BridgeApp  # noqa: E402
from coolmuscle.frontends.ethercat.transport import (  # noqa: E402
    MODEL_PRIORITY,
    CycleLateness,
    cycle_collector,
)
from coolmuscle.sim.kernel import Kernel  # noqa: E402
from coolmuscle.sim.realtime import RealtimeClock  # noqa: E402

CYCLE_NS = 1_000_000
GOAL_US = 50.0
AXES = 4
#: Run the collector between cycles only with at least this much wall time to spare (s).
GC_SLACK = 0.0005


def realtime() -> bool:
    """SCHED_FIFO at the transport's model priority, as ``sim --ethercat`` (when allowed)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(MODEL_PRIORITY))
    except (AttributeError, OSError):
        return False
    return True


def steal_ticks() -> int:
    """CPU time the hypervisor gave to others, all CPUs, in clock ticks (0 if unknown)."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8])
    except (OSError, IndexError, ValueError):
        return 0


def wait_until(due: float, spin: float) -> None:
    """Sleep until ``spin`` s before ``due``, then spin to it."""
    now = time.perf_counter()
    if due - now > spin:
        time.sleep(due - now - spin)
    while time.perf_counter() < due:
        pass


def triangle(i: int) -> int:
    """+/-4,000 pulses at 2 pulses a cycle."""
    phase = i % 8000
    return 2 * phase if phase < 2000 else 8000 - 2 * phase if phase < 6000 else 2 * phase - 16000


class Collections:
    """The collections that start while it is installed: how many by generation, and
    the longest (gc.callbacks)."""

    def __init__(self) -> None:
        self.count = [0, 0, 0]
        self.longest = 0.0
        self._began = 0.0

    def __call__(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self._began = time.perf_counter()
        else:
            self.count[info["generation"]] += 1
            self.longest = max(self.longest, time.perf_counter() - self._began)


def run(seconds: float, moving: bool, spin: float, between: bool) -> dict[str, Any]:
    kernel = Kernel()
    chain = Chain(kernel, AXES, firmware="cm2")
    app = BridgeApp(chain, "EB02")
    od = app.dictionary

    def image(cw: int, target: int) -> bytes:
        return struct.pack("<" + "Hi" * AXES, *([cw, target] * AXES))

    def frame(cw: int, target: int) -> None:   # the frame thread's part: the output image
        data = image(cw, target)
        od.unpack_outputs(data)
        app.outputs(data)

    app.start_cycles(CYCLE_NS)                 # the bridge's cycle, as sim --ethercat runs it
    for cw in (0x06, 0x07, 0x0F):              # 6.1.2, virtual time
        frame(cw, 0)
        kernel.run(until=kernel.now + 5 * CYCLE_NS)
    cycles = int(seconds * 1000)
    cpu = 0.0
    t0_cpu = time.process_time()
    clock = RealtimeClock(kernel, clock=time.perf_counter)     # the wall clock <-> kernel time
    t0_wall, base_virtual = clock.wall_at(kernel.now), kernel.now
    late = CycleLateness(clock, CYCLE_NS / 1e9)    # the transport's count of late cycles
    lateness: list[float] = []

    def note() -> None:
        late.note(kernel.now)
        lateness.append(clock.lateness(kernel.now))

    app.start_cycles(CYCLE_NS, note)
    undo = cycle_collector()                   # as the transport does once it has started
    if between:
        gc.disable()                           # collected between cycles (below)
    thresholds = gc.get_threshold()
    collections = Collections()
    gc.callbacks.append(collections)
    steal0 = steal_ticks()
    for i in range(cycles):
        due = clock.wall_at(base_virtual + (i + 1) * CYCLE_NS)
        wait_until(due, spin)
        c0 = time.process_time()
        frame(0x0F, triangle(i) if moving else 0)
        kernel.run(until=min(clock.virtual_at(time.perf_counter()),
                             base_virtual + cycles * CYCLE_NS))
        cpu += time.process_time() - c0
        counts = gc.get_count()
        if (between and counts[0] > thresholds[0]
                and clock.wall_at(kernel.now + CYCLE_NS) - time.perf_counter() > GC_SLACK):
            gc.collect(2 if counts[2] >= thresholds[2] else 1 if counts[1] >= thresholds[1]
                       else 0)
    kernel.run(until=base_virtual + cycles * CYCLE_NS)
    wall = time.perf_counter() - t0_wall
    total_cpu = time.process_time() - t0_cpu
    steal = (steal_ticks() - steal0) / os.sysconf("SC_CLK_TCK")
    app.stop_cycles()
    gc.callbacks.remove(collections)
    gc.enable()
    undo()
    lateness.sort()
    positions = [chain.snapshot(a).position for a in range(1, AXES + 1)]
    words = [od.get(0x6041 + 0x800 * a) for a in range(AXES)]
    return {"cycles": cycles, "missed": late.late, "cpu_share": total_cpu / wall,
            "axis_cycle_us": cpu / cycles / AXES * 1e6, "wall": wall, "steal": steal,
            "p99_ms": lateness[int(0.99 * (len(lateness) - 1))] * 1e3,
            "worst_ms": lateness[-1] * 1e3,
            "positions": positions, "words": words,
            "collections": collections.count, "longest_gc_ms": collections.longest * 1e3}


def run_empty(seconds: float, spin: float) -> dict[str, Any]:
    """The same wait for each 1 ms slot at the same priority, with nothing in the cycle:
    the cycles this machine itself starts more than a cycle late (its stalls, the
    hypervisor's steal), the floor under the bridge's own count."""
    cycles = int(seconds * 1000)
    cycle = CYCLE_NS / 1e9
    lateness: list[float] = []
    gc.freeze()
    gc.disable()
    steal0 = steal_ticks()
    t0 = time.perf_counter()
    for i in range(cycles):
        due = t0 + (i + 1) * cycle
        wait_until(due, spin)
        lateness.append(time.perf_counter() - due)
    steal = (steal_ticks() - steal0) / os.sysconf("SC_CLK_TCK")
    gc.enable()
    gc.unfreeze()
    missed = sum(late > cycle for late in lateness)
    lateness.sort()
    return {"cycles": cycles, "missed": missed, "steal": steal,
            "p99_ms": lateness[int(0.99 * (len(lateness) - 1))] * 1e3,
            "worst_ms": lateness[-1] * 1e3}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--spin-us", type=float, default=300.0,
                    help="spin this long before each cycle instead of sleeping (0: sleep)")
    ap.add_argument("--collector", choices=("shipped", "between"), default="shipped",
                    help="the collector as sim --ethercat sets it, or run between cycles")
    args = ap.parse_args()
    between = args.collector == "between"
    fifo = realtime()
    load = os.getloadavg()
    moving = run(args.seconds, True, args.spin_us / 1e6, between)
    holding = run(args.seconds, False, args.spin_us / 1e6, between)
    empty = run_empty(args.seconds, args.spin_us / 1e6)
    print(f"4-axis bridge in csp at 1 ms, {args.seconds:g} s each (manual 6.3); "
          f"{'SCHED_FIFO' if fifo else 'normal priority (no CAP_SYS_NICE)'}, "
          f"spin {args.spin_us:g} us; collector {args.collector}; "
          f"load average {load[0]:.2f} before, "
          f"{os.getloadavg()[0]:.2f} after")
    print(f"{'':24s}{'csp moving':>14s}{'csp holding':>14s}{'empty cycle':>14s}{'goal':>10s}")
    rows = (moving, holding, empty)
    print(f"{'missed cycles':24s}" + "".join(f"{r['missed']:>14d}" for r in rows) + f"{0:>10d}")
    print(f"{'missed share':24s}" + "".join(f"{r['missed'] / r['cycles']:>14.2%}" for r in rows)
          + f"{0.001:>10.1%}")
    print(f"{'late by, p99 (ms)':24s}" + "".join(f"{r['p99_ms']:>14.3f}" for r in rows))
    print(f"{'late by, worst (ms)':24s}" + "".join(f"{r['worst_ms']:>14.3f}" for r in rows))
    print(f"{'steal (CPU s)':24s}" + "".join(f"{r['steal']:>14.2f}" for r in rows))
    floor = empty["missed"] / empty["cycles"]
    print(f"{'missed beyond the empty':24s}" + "".join(
        f"{r['missed'] / r['cycles'] - floor:>14.2%}" for r in rows[:2]))
    print(f"{'collections (gen 0/1/2)':24s}" + "".join(
        f"{'/'.join(map(str, r['collections'])):>14s}" for r in rows[:2]))
    print(f"{'longest collection (ms)':24s}" + "".join(
        f"{r['longest_gc_ms']:>14.3f}" for r in rows[:2]))
    print(f"{'CPU share':24s}{moving['cpu_share']:>14.1%}{holding['cpu_share']:>14.1%}")
    print(f"{'per axis-cycle (us)':24s}{moving['axis_cycle_us']:>14.1f}"
          f"{holding['axis_cycle_us']:>14.1f}{GOAL_US:>10.0f}")
    print(f"{'ratio to the 50 us goal':24s}{moving['axis_cycle_us'] / GOAL_US:>14.2f}"
          f"{holding['axis_cycle_us'] / GOAL_US:>14.2f}{1:>10.2f}")
    print(f"{'4 axes / 1 ms cycle':24s}{4 * moving['axis_cycle_us'] / 1000:>14.2f}"
          f"{4 * holding['axis_cycle_us'] / 1000:>14.2f}")
    print(f"statuswords moving: {[hex(w) for w in moving['words']]}, "
          f"positions {moving['positions']}")


if __name__ == "__main__":
    main()
