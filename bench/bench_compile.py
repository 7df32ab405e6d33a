"""What each lever of the compile costs and gives (docs/performance.md "Compiled hot
modules": the table of levers).

Run: ``PYTHONPATH=src python bench/bench_compile.py [--plans NAME,...] [--no-speed]
[--time ROUNDS]``
(mypy 1.19 and a C compiler needed: the ``accel`` extra).  For each plan of
:data:`PLANS` it compiles the hot modules as the package build does
(coolmuscle/tools/accel/compiler.py, into a temporary folder) and records:

* the compile's wall time, its CPU time (user + system of mypyc and every C compiler
  process: the steady figure on a shared machine; on an idle machine with two CPUs the
  wall time of a parallel compile is about the mypyc step plus half the C compile's CPU)
  and how long the mypyc step took;
* with ``--time ROUNDS``, the CPU time of a cycle of the bridge in csp on each plan's
  code, the plans run in turn (``A B C A B C ...``), with each one's ratio to the first
  round by round (link-time optimisation saves more time than instructions: the calls
  between the modules become direct, without the indirection of exported symbols);
* the speed of the code it made: the instructions (callgrind, which a loaded machine
  does not disturb) of three workloads run on a copy of the package with those compiled
  modules, less those of the same process doing none of the work (start and imports):
  a 15-motor chain looping PTP banks (2 simulated s), four csp axes (300 cycles of 1 ms),
  and the EtherCAT bridge in csp (300 cycles).  The sources (``COOLMUSCLE_PURE=1``)
  are measured once beside them.

It prints one table (and ``--json`` writes the figures).  A few minutes a plan.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "src"))

import coolmuscle._accel as accel  # noqa: E402
from coolmuscle.tools.accel import compiler  # noqa: E402

#: The EtherCAT bridge's modules, and everything else.
BRIDGE = ("frontends.ethercat.",)
MODEL = ("",)

#: The plans measured: name -> (what it is, plan, modules left out).
PLANS: dict[str, tuple[str, compiler.Plan, tuple[str, ...]]] = {
    "one-O3": ("one library, one C file, -O3 (the first build)",
               compiler.Plan(jobs=1, link_time=False), ()),
    "multi-O3": ("one library, a C file a module, -O3, 2 jobs, each file optimised alone",
                 compiler.Plan(multi_file=True, jobs=2, link_time=False), ()),
    "multi-O3-lto": ("the same, optimised as a whole when linked, its symbols hidden "
                     "(the build's plan)", compiler.Plan(multi_file=True, jobs=2), ()),
    "multi-O2": ("a C file a module at -O2",
                 compiler.Plan(multi_file=True, jobs=2, opt_level="2", link_time=False), ()),
    "multi-O1": ("a C file a module at -O1",
                 compiler.Plan(multi_file=True, jobs=2, opt_level="1", link_time=False), ()),
    "one-O1": ("one library, one C file, -O1",
               compiler.Plan(jobs=2, opt_level="1", link_time=False), ()),
    "separate-O3": ("a library a module (separate), -O3, 2 jobs",
                    compiler.Plan(separate=True, jobs=2, link_time=False), ()),
    "groups-O3": ("two libraries (model, bridge), a C file a module, -O3, 2 jobs",
                  compiler.Plan(multi_file=True, jobs=2, link_time=False,
                                groups=(("coolmuscle._hot_bridge", BRIDGE),
                                        ("coolmuscle._hot", MODEL))), ()),
    "nobridge-O3": ("without the bridge's 8 modules, a C file a module, -O3, 2 jobs",
                    compiler.Plan(multi_file=True, jobs=2, link_time=False), BRIDGE),
}

#: One workload, run in a fresh interpreter on a package copy: ``size`` units of work.
WORKLOAD = r"""
import math, struct, sys
from coolmuscle.chain.daisy import Chain
name, size = sys.argv[1], int(sys.argv[2])
if name == "chain15":
    chain = Chain(motors=15)
    for n in range(1, 16):
        for line in (f"S1.{n}={100 + n}, A1.{n}=100, P1.{n}=10000, P2.{n}=0", f"B1.{n}",
                     "X0", f"S1.{n}, A1.{n}, P1.{n}", f"P2.{n}", "X-", "END"):
            chain.execute(line)
    for n in range(1, 16):
        chain.execute(f"[1.{n}")
    chain.kernel.run(until=size * 1_000_000)
elif name == "stream4":
    chain = Chain(motors=4)
    streams = [chain.target_stream(n) for n in range(1, 5)]
    for i in range(size):
        for n, stream in enumerate(streams, 1):
            half = 2000.0 + 50.0 * n
            stream.push(round(half - half * math.cos(2.0 * math.pi * i / 4000.0)))
        chain.kernel.advance(1_000_000)
elif name in ("bridge", "bridge-time"):
    import time
    from coolmuscle.frontends.ethercat.bridge.app import BridgeApp
    chain = Chain(motors=4)
    app = BridgeApp(chain, "EB02")
    od = app.dictionary
    app.start_cycles()
    def ms(cw, target):
        od.unpack_outputs(struct.pack("<" + "Hi" * 4, *([cw, target] * 4)))
        chain.kernel.advance(1_000_000)
        od.pack_inputs()
    for cw in (0x06, 0x07, 0x0F):
        for _ in range(5):
            ms(cw, 0)
    start = time.process_time()
    for i in range(size):
        ms(0x0F, 3 * (i % 1000))
    if name == "bridge-time":
        print("us-per-cycle", (time.process_time() - start) / size * 1e6)
"""

#: Workload -> (units measured, what a unit is).
WORKLOADS = {"chain15": (2000, "ms"), "stream4": (300, "cycles"), "bridge": (300, "cycles")}
#: Cycles of the bridge a timed run (``--time``) takes.
TIMED_CYCLES = 20_000


def compile_plan(plan: compiler.Plan, leave_out: tuple[str, ...], out: Path
                 ) -> dict[str, float]:
    """Compile into ``out`` (a package folder); wall, CPU and mypyc seconds."""
    modules = [m for m in accel.MODULES
               if not any(m.removeprefix("coolmuscle.").startswith(p) for p in leave_out)]
    lines: list[str] = []
    saved = accel.MODULES
    accel.MODULES = modules                 # the child compiles what the list names
    try:
        wall, before = time.monotonic(), resource.getrusage(resource.RUSAGE_CHILDREN)
        outcome = compiler.build(accel, out, in_place=False, plan=plan, log=lines.append)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    finally:
        accel.MODULES = saved
    if not outcome.compiled:
        raise SystemExit(f"the compile failed: {outcome.reason}\n" + "\n".join(lines[-20:]))
    mypyc = next((float(m.group(1)) for line in lines
                  if (m := re.match(r"\[\s*(\d+) s\] mypyc: done", line))), float("nan"))
    return {"wall": time.monotonic() - wall, "mypyc": mypyc,
            "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)}


def package_copy(built: Path | None, where: Path, leave_out: tuple[str, ...] = ()) -> Path:
    """A copy of the package (its ``src`` folder) with ``built``'s compiled files; the
    modules ``leave_out`` names are off its module list too (or its stamp is refused)."""
    src = where / "src"
    package = src / "coolmuscle"
    shutil.copytree(ROOT / "src" / "coolmuscle", package, ignore=shutil.ignore_patterns(
        "*.so", "_build_stamp.py", "__pycache__", ".accel-build.lock"))
    if leave_out:
        lines = (package / "_accel.py").read_text().splitlines(keepends=True)
        (package / "_accel.py").write_text("".join(
            line for line in lines
            if not any(line.strip().startswith(f'"coolmuscle.{p}') for p in leave_out)))
    if built is not None:
        for path in built.rglob("*"):
            if path.is_file():
                target = package / path.relative_to(built)
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(path, target)
    check = subprocess.run([sys.executable, "-c", "import coolmuscle._accel as a, coolmuscle; "
                            "print(a.active())"], capture_output=True, text=True,
                           env=dict(os.environ, PYTHONPATH=str(src), COOLMUSCLE_PURE="0"))
    assert check.stdout.strip() == str(built is not None), (check.stdout, check.stderr)
    return src


def instructions(src: Path, name: str, size: int, pure: bool) -> int:
    """Instructions callgrind counts for one run of the workload."""
    env = dict(os.environ, PYTHONPATH=str(src), COOLMUSCLE_PURE="1" if pure else "0")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        done = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
                               sys.executable, "-c", WORKLOAD, name, str(size)],
                              env=env, capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"{name} failed:\n{done.stderr[-2000:]}")
        match = re.search(r"^summary: (\d+)", out.read_text(), re.MULTILINE)
        assert match is not None, "no callgrind summary"
        return int(match.group(1))


def speed(src: Path, pure: bool = False) -> dict[str, float]:
    """Millions of instructions of each workload's units (a run less the empty run)."""
    return {name: (instructions(src, name, size, pure) - instructions(src, name, 0, pure)) / 1e6
            for name, (size, _unit) in WORKLOADS.items()}


def cpu_per_cycle(src: Path) -> float:
    """CPU microseconds a cycle of the bridge in csp (4 axes moving) takes, in one run."""
    env = dict(os.environ, PYTHONPATH=str(src), COOLMUSCLE_PURE="0")
    done = subprocess.run([sys.executable, "-c", WORKLOAD, "bridge-time", str(TIMED_CYCLES)],
                          env=env, capture_output=True, text=True, check=True)
    return float(done.stdout.split("us-per-cycle")[1])


def timed(copies: dict[str, Path], rounds: int) -> None:
    """Each plan's code timed in turn, ``rounds`` times (A B C A B C ...: a machine
    whose speed drifts slows them alike); medians, and each plan's ratio to the first
    taken round by round."""
    names = list(copies)
    runs: dict[str, list[float]] = {name: [] for name in names}
    for _ in range(rounds):
        for name in names:
            runs[name].append(cpu_per_cycle(copies[name]))
    first = runs[names[0]]
    print(f"\nCPU time a cycle of the bridge in csp ({TIMED_CYCLES} cycles a run, "
          f"{rounds} runs each, taken in turn):")
    print(f"{'plan':<13} {'median us':>9} {'to ' + names[0]:>16}  (ratios: min-max)")
    for name in names:
        ratios = sorted(a / b for a, b in zip(runs[name], first, strict=True))
        print(f"{name:<13} {statistics.median(runs[name]):>9.1f} "
              f"{statistics.median(ratios):>16.3f}  ({ratios[0]:.3f}-{ratios[-1]:.3f})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--plans", default=",".join(PLANS))
    parser.add_argument("--no-speed", action="store_true")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--time", type=int, default=0, metavar="ROUNDS",
                        help="also time the bridge's cycle on each plan's code, in turn")
    args = parser.parse_args()
    chosen = args.plans.split(",")
    rows: dict[str, dict[str, float]] = {}
    copies: dict[str, Path] = {}
    with tempfile.TemporaryDirectory(prefix="bench-compile-") as tmp:
        if not args.no_speed:
            rows["sources"] = speed(package_copy(None, Path(tmp) / "pure"), pure=True)
            print("sources:", json.dumps(rows["sources"]), flush=True)
        for name in chosen:
            _what, plan, leave_out = PLANS[name]
            out = Path(tmp) / name / "built"
            row = compile_plan(plan, leave_out, out)
            if not args.no_speed or args.time:
                copies[name] = package_copy(out, Path(tmp) / name, leave_out)
            if not args.no_speed:
                row |= speed(copies[name])
            rows[name] = row
            print(f"{name}:", json.dumps(row), flush=True)
        if args.time:
            timed(copies, args.time)
    print(f"\nload average after: {os.getloadavg()}")
    head = f"{'plan':<13} {'wall s':>7} {'CPU s':>6} {'mypyc s':>7}"
    units = "  ".join(f"{n} M/{size} {unit}" for n, (size, unit) in WORKLOADS.items())
    print(f"{head}  instructions: {units}")
    for name, row in rows.items():
        nan = float("nan")
        figures = "  ".join(f"{row.get(n, nan):>12.1f}" for n in WORKLOADS)
        print(f"{name:<13} {row.get('wall', nan):>7.1f} {row.get('cpu', nan):>6.1f}"
              f" {row.get('mypyc', nan):>7.0f}  {figures}")
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
