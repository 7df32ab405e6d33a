"""Benchmark: bridges in csp at 1 ms (ethercat-bridge-users-guide.txt 6.3).

Bridges in a line (``--bridges N``, default 8: 32 axes, a machine's line; 1: the
4-axis bridge), each with its chain of four CM2, all on one kernel as ``sim --ethercat
--bridges`` runs them (:class:`BridgeSegment`), in one thread paced to the wall clock:
the bridges' cycle is one kernel event every 1 ms of virtual time (the CM port's own
cycle); every wall millisecond each bridge's RxPDO image of that millisecond arrives
(every axis in Operation enabled, each following its own cosine ramp of about 4,000
pulses in 2 s and back, a new target every cycle: no two axes alike, so no solved
motion is shared) and the kernel runs to the wall-clock instant.  No network: this is
the model's side of the 1 ms cycle, the part that decides whether the axes keep up.

Printed side by side, for the axes following (csp moving) and holding (same target):

* missed cycles: cycles that started more than one cycle after they were due (they
  still run, back to back, as in the transport: virtual time does not skip them);
* CPU share: process CPU time over wall time (the spin before each cycle included);
* the model's time per cycle (CPU time of the bridges' cycle with its kernel run and the
  output images taken in) against the 0.35 ms goal of 32 axes, and per axis-cycle; the
  master's own part, its targets computed and packed into each bridge's image, is done
  before the cycle's slot and printed on its own (a master does it on its machine);
* what a late cycle was late by (p99, worst) and the CPU time the machine's hypervisor
  took from this virtual machine meanwhile (steal, /proc/stat);
* the same for an empty cycle: the same wait for each slot at the same priority with
  nothing to do, the cycles the machine itself starts late (its stalls, the steal), the
  floor under the bridges' count; and how far above that floor each run is (goal: at
  most 0.1 percentage point).

The loop runs as ``sim --ethercat`` runs the model's thread where the system allows it
(root, CAP_SYS_NICE): under SCHED_FIFO at the transport's priority.  It waits for a
cycle by sleeping until ``--spin-us`` before it and spinning the rest (a sleeping
virtual CPU wakes 0.1-1 ms late); and the cyclic collector is set as ``sim --ethercat``
sets it (``transport.cycle_collector``: what ships is measured).  The collections that
start during each run are counted by generation with the longest one
(``gc.callbacks``).  ``--collector between`` runs the collector between cycles instead
(automatic collection off, a collection when the next cycle is at least ``GC_SLACK``
away), for comparison.

    PYTHONPATH=src python bench/bench_ethercat_csp.py [--seconds 60] [--bridges 8] \
        [--collector between]
    PYTHONPATH=src python bench/bench_ethercat_csp.py --virtual 2000   # no pacing
"""

from __future__ import annotations

import argparse
import gc
import math
import os
import struct
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from coolmuscle.chain import Chain  # noqa: E402
from coolmuscle.frontends.ethercat.bridge.segment import BridgeSegment  # noqa: E402
from coolmuscle.frontends.ethercat.transport import (  # noqa: E402
    MODEL_PRIORITY,
    CycleLateness,
    cycle_collector,
)
from coolmuscle.sim.kernel import Kernel  # noqa: E402
from coolmuscle.sim.realtime import RealtimeClock  # noqa: E402

CYCLE_NS = 1_000_000
#: The model's side of a cycle of 32 axes (8 bridges) at most, and per axis-cycle.
GOAL_CYCLE_US = 350.0
GOAL_AXIS_US = GOAL_CYCLE_US / 32
#: A bridge run's late share may be the empty cycle's plus this (a share, 0.1 pp).
GOAL_LATE_ABOVE = 0.001
AXES = 4                                   # a bridge's
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


def ramp(i: int, axis: int) -> int:
    """Axis ``axis``'s (1, 2, ...) target of cycle ``i``: 0 -> 4,000 (+ 50 axis) -> 0
    pulses, 2 s each way (a cosine): every axis's cycles differ from every other's."""
    half = 2000.0 + 25.0 * axis
    return round(half - half * math.cos(2.0 * math.pi * i / 4000.0))


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


def run(seconds: float, moving: bool, spin: float, bridges: int,
        between: bool) -> dict[str, Any]:
    kernel = Kernel()
    chains = [Chain(kernel, AXES, firmware="cm2") for _ in range(bridges)]
    segment = BridgeSegment(chains, ("EB02",) * bridges)
    apps = segment.apps
    ods = [app.dictionary for app in apps]

    def images(cw: int, i: int) -> list[bytes]:    # the master's part: its targets, packed
        return [struct.pack("<" + "Hi" * AXES, *(v for a in range(AXES) for v in (
            cw, ramp(i, AXES * n + a + 1) if moving else 0))) for n in range(bridges)]

    def take(data: list[bytes]) -> None:       # the frame thread's part: the output images
        for image, app, od in zip(data, apps, ods):
            od.unpack_outputs(image)
            app.outputs(image)

    def frame(cw: int, i: int) -> None:
        take(images(cw, i))

    segment.start_cycles(CYCLE_NS)             # the bridges' cycle, as sim --ethercat runs it
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

    segment.start_cycles(CYCLE_NS, note)
    undo = cycle_collector()                   # as the transport does once it has started
    if between:
        gc.disable()                           # collected between cycles (below)
    thresholds = gc.get_threshold()
    collections = Collections()
    gc.callbacks.append(collections)
    steal0 = steal_ticks()
    master = 0.0
    for i in range(cycles):
        due = clock.wall_at(base_virtual + (i + 1) * CYCLE_NS)
        m0 = time.process_time()
        data = images(0x0F, i)                 # the master's frame of this cycle
        master += time.process_time() - m0
        wait_until(due, spin)
        c0 = time.process_time()
        take(data)
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
    segment.stop_cycles()
    gc.callbacks.remove(collections)
    gc.enable()
    undo()
    lateness.sort()
    positions = [chain.snapshot(a).position for chain in chains for a in range(1, AXES + 1)]
    words = [od.get(0x6041 + 0x800 * a) for od in ods for a in range(AXES)]
    return {"cycles": cycles, "missed": late.late, "cpu_share": total_cpu / wall,
            "cycle_us": cpu / cycles * 1e6, "axis_cycle_us": cpu / cycles / AXES / bridges * 1e6,
            "master_us": master / cycles * 1e6,
            "wall": wall, "steal": steal,
            "p99_ms": lateness[int(0.99 * (len(lateness) - 1))] * 1e3,
            "worst_ms": lateness[-1] * 1e3,
            "positions": positions, "words": words,
            "collections": collections.count, "longest_gc_ms": collections.longest * 1e3}


def run_virtual(cycles: int, bridges: int) -> tuple[float, float]:
    """The moving run's work in virtual time, without pacing or waiting: CPU seconds of
    ``cycles`` cycles after 200 to start (the steady measure: under callgrind, two
    lengths subtracted cancel the start), and of a full collection every 100 cycles
    between them (what ``--collector between`` would cost)."""
    kernel = Kernel()
    chains = [Chain(kernel, AXES, firmware="cm2") for _ in range(bridges)]
    segment = BridgeSegment(chains, ("EB02",) * bridges)
    apps = segment.apps
    ods = [app.dictionary for app in apps]

    def images(cw: int, i: int) -> list[bytes]:
        return [struct.pack("<" + "Hi" * AXES, *(v for a in range(AXES) for v in (
            cw, ramp(i, AXES * n + a + 1)))) for n in range(bridges)]

    def take(data: list[bytes]) -> None:
        for image, app, od in zip(data, apps, ods):
            od.unpack_outputs(image)
            app.outputs(image)

    def frame(cw: int, i: int) -> None:
        take(images(cw, i))

    segment.start_cycles(CYCLE_NS)
    for cw in (0x06, 0x07, 0x0F):
        frame(cw, 0)
        kernel.run(until=kernel.now + 5 * CYCLE_NS)
    for i in range(200):
        frame(0x0F, i)
        kernel.advance(CYCLE_NS)
    gc.freeze()
    gc.disable()
    cpu = collect = 0.0
    for i in range(200, 200 + cycles):
        data = images(0x0F, i)                 # the master's part, not timed
        c0 = time.process_time()
        take(data)
        kernel.advance(CYCLE_NS)
        c1 = time.process_time()
        cpu += c1 - c0
        if i % 100 == 0:
            gc.collect()
            collect += time.process_time() - c1
    gc.enable()
    gc.unfreeze()
    return cpu, collect


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
    ap.add_argument("--bridges", type=int, default=8, help="bridges in the line (4 axes each)")
    ap.add_argument("--spin-us", type=float, default=300.0,
                    help="spin this long before each cycle instead of sleeping (0: sleep)")
    ap.add_argument("--virtual", type=int, metavar="CYCLES", default=0,
                    help="only the moving work in virtual time, CYCLES cycles (profiling)")
    ap.add_argument("--collector", choices=("shipped", "between"), default="shipped",
                    help="the collector as sim --ethercat sets it, or run between cycles")
    args = ap.parse_args()
    between = args.collector == "between"
    if args.virtual:
        cpu, collect = run_virtual(args.virtual, args.bridges)
        print(f"{args.bridges} bridge(s) in virtual time: {cpu / args.virtual * 1e6:.1f} us "
              f"per cycle, {cpu / args.virtual / AXES / args.bridges * 1e6:.2f} us per "
              f"axis-cycle; the collector between cycles {collect / args.virtual * 1e6:.1f} "
              "us per cycle")
        return
    fifo = realtime()
    load = os.getloadavg()
    axes = AXES * args.bridges
    moving = run(args.seconds, True, args.spin_us / 1e6, args.bridges, between)
    holding = run(args.seconds, False, args.spin_us / 1e6, args.bridges, between)
    empty = run_empty(args.seconds, args.spin_us / 1e6)
    print(f"{args.bridges} bridge(s), {axes} axes in csp at 1 ms, {args.seconds:g} s each "
          f"(manual 6.3); {'SCHED_FIFO' if fifo else 'normal priority (no CAP_SYS_NICE)'}, "
          f"spin {args.spin_us:g} us; collector {args.collector}; "
          f"load average {load[0]:.2f} before, "
          f"{os.getloadavg()[0]:.2f} after")
    print(f"{'':28s}{'csp moving':>14s}{'csp holding':>14s}{'empty cycle':>14s}{'goal':>10s}")
    rows = (moving, holding, empty)
    print(f"{'missed cycles':28s}" + "".join(f"{r['missed']:>14d}" for r in rows))
    print(f"{'missed share':28s}" + "".join(f"{r['missed'] / r['cycles']:>14.3%}" for r in rows))
    print(f"{'late by, p99 (ms)':28s}" + "".join(f"{r['p99_ms']:>14.3f}" for r in rows))
    print(f"{'late by, worst (ms)':28s}" + "".join(f"{r['worst_ms']:>14.3f}" for r in rows))
    print(f"{'steal (CPU s)':28s}" + "".join(f"{r['steal']:>14.2f}" for r in rows))
    floor = empty["missed"] / empty["cycles"]
    print(f"{'missed beyond the empty':28s}" + "".join(
        f"{r['missed'] / r['cycles'] - floor:>14.3%}" for r in rows[:2])
        + f"{'':14s}{GOAL_LATE_ABOVE:>10.1%}")
    print(f"{'collections (gen 0/1/2)':28s}" + "".join(
        f"{'/'.join(map(str, r['collections'])):>14s}" for r in rows[:2]))
    print(f"{'longest collection (ms)':28s}" + "".join(
        f"{r['longest_gc_ms']:>14.3f}" for r in rows[:2]))
    print(f"{'CPU share':28s}{moving['cpu_share']:>14.1%}{holding['cpu_share']:>14.1%}")
    print(f"{'model time per cycle (us)':28s}{moving['cycle_us']:>14.1f}"
          f"{holding['cycle_us']:>14.1f}{'':14s}{GOAL_CYCLE_US * axes / 32:>10.0f}")
    print(f"{'per axis-cycle (us)':28s}{moving['axis_cycle_us']:>14.2f}"
          f"{holding['axis_cycle_us']:>14.2f}{'':14s}{GOAL_AXIS_US:>10.2f}")
    print(f"{'share of the 1 ms cycle':28s}{moving['cycle_us'] / 1000:>14.2f}"
          f"{holding['cycle_us'] / 1000:>14.2f}")
    print(f"{'the master builds (us)':28s}{moving['master_us']:>14.1f}"
          f"{holding['master_us']:>14.1f}")
    print(f"statuswords moving (first bridge): {[hex(w) for w in moving['words'][:AXES]]}, "
          f"positions {moving['positions'][:AXES]}")


if __name__ == "__main__":
    main()
