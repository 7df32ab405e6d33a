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
* CPU share: process CPU time over wall time;
* the cost of one axis-cycle (CPU time of a bridge cycle with its kernel run, / 4)
  against the 50 us goal of issue 12 item 9, and the 1 ms cycle it must fit in.

    PYTHONPATH=src python bench/bench_ethercat_csp.py [--seconds 60]
"""

from __future__ import annotations

import argparse
import gc
import struct
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from coolmuscle.chain import Chain  # noqa: E402
from coolmuscle.frontends.ethercat.app import BridgeApp  # noqa: E402
from coolmuscle.frontends.ethercat.transport import CycleLateness  # noqa: E402
from coolmuscle.sim.kernel import Kernel  # noqa: E402
from coolmuscle.sim.realtime import RealtimeClock  # noqa: E402

CYCLE_NS = 1_000_000
GOAL_US = 50.0
AXES = 4


def triangle(i: int) -> int:
    """+/-4,000 pulses at 2 pulses a cycle."""
    phase = i % 8000
    return 2 * phase if phase < 2000 else 8000 - 2 * phase if phase < 6000 else 2 * phase - 16000


def run(seconds: float, moving: bool) -> dict[str, float]:
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
    app.start_cycles(CYCLE_NS, lambda: late.note(kernel.now))
    gc.freeze()                                # as the transport does once it has started
    for i in range(cycles):
        due = clock.wall_at(base_virtual + (i + 1) * CYCLE_NS)
        now = time.perf_counter()
        if now < due:
            time.sleep(due - now)
        c0 = time.process_time()
        frame(0x0F, triangle(i) if moving else 0)
        kernel.run(until=min(clock.virtual_at(time.perf_counter()),
                             base_virtual + cycles * CYCLE_NS))
        cpu += time.process_time() - c0
    kernel.run(until=base_virtual + cycles * CYCLE_NS)
    wall = time.perf_counter() - t0_wall
    total_cpu = time.process_time() - t0_cpu
    app.stop_cycles()
    gc.unfreeze()
    positions = [chain.snapshot(a).position for a in range(1, AXES + 1)]
    words = [od.get(0x6041 + 0x800 * a) for a in range(AXES)]
    return {"cycles": cycles, "missed": late.late, "cpu_share": total_cpu / wall,
            "axis_cycle_us": cpu / cycles / AXES * 1e6, "wall": wall,
            "positions": positions, "words": words}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    args = ap.parse_args()
    moving = run(args.seconds, True)
    holding = run(args.seconds, False)
    print(f"4-axis bridge in csp at 1 ms, {args.seconds:g} s each (manual 6.3)")
    print(f"{'':24s}{'csp moving':>14s}{'csp holding':>14s}{'goal':>10s}")
    print(f"{'missed cycles':24s}{moving['missed']:>14d}{holding['missed']:>14d}{0:>10d}")
    print(f"{'missed share':24s}{moving['missed'] / moving['cycles']:>14.2%}"
          f"{holding['missed'] / holding['cycles']:>14.2%}")
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
