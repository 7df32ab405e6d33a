"""Speed where users feel it (issue 18): every row of the issue's table in one run.

Run: ``PYTHONPATH=src python bench/bench_speed.py [--baseline REF] [--repeat N] [--quick]``
(about five minutes; ``--quick`` divides the simulated times by ten).

Each row is measured on this tree twice, running its sources (``COOLMUSCLE_PURE=1``)
and its compiled hot modules (coolmuscle/_accel.py; build them first with ``python -m
coolmuscle.tools.accel build``), and, side by side in the same run, on a baseline
tree (``--baseline REF``, default :data:`BASELINE`: main before the issue-18 work),
extracted with ``git archive`` into a temporary directory; the trees are run in turn,
``--repeat`` times each, and the best (least disturbed) run of each is shown, next to
the goal.  Without git or the commit (``--baseline none``) the baseline column shows
the figure the issue recorded.  Every figure comes from a fresh interpreter
(:mod:`speed_worker` or the ``coolmuscle`` command itself), with byte-compiled modules
as an installed package has them.

Rows (docs/performance.md):

1. ``coolmuscle run`` on a script whose one motor loops a PTP bank of 1.1 s moves,
   10 simulated hours (``--until 36000``): simulated / wall time, start included.
2. ``coolmuscle run --motors 15``, every motor looping its PTP bank, 600 simulated s.
3. bench_chain.py's 15-motor chain, 60 simulated s, in process.
4. The start of ``coolmuscle run`` on a one-line script (``?96.1``): wall seconds.
5. The cost of one move through a program bank (planner, servo and load model,
   in-position, report, next line), with kernel events and Python calls per move.
6. ``Chain.target_stream`` with a new target every 1 ms on 4 motors (csp, issue 12
   item 9): wall time per axis-cycle.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
#: main before the issue-18 work (the architecture refactor, e2123c0).
BASELINE = "e2123c0"

B2_SCRIPT = """\
S1.1=100
A1.1=100
P1.1=10000
P2.1=0
B1.1
X0
S1.1, A1.1, P1.1
P2.1
X-
END
[1.1
"""


def chain_script(motors: int) -> str:
    lines = []
    for n in range(1, motors + 1):
        lines.append(f"S1.{n}={100 + n}, A1.{n}=100, P1.{n}=10000, P2.{n}=0")
        lines += [f"B1.{n}", "X0", f"S1.{n}, A1.{n}, P1.{n}", f"P2.{n}", "X-", "END"]
    lines += [f"[1.{n}" for n in range(1, motors + 1)]
    return "\n".join(lines) + "\n"


class Tree:
    """A source tree to measure (its ``src`` on PYTHONPATH, byte code allowed)."""

    def __init__(self, name: str, root: Path, *, pure: bool = False) -> None:
        self.name = name
        self.root = root
        self.env = dict(os.environ)
        self.env.pop("PYTHONDONTWRITEBYTECODE", None)
        self.env.pop("COOLMUSCLE_PURE", None)
        self.env["PYTHONPATH"] = str(root / "src")
        if pure:                      # the sources, not the compiled modules (_accel.py)
            self.env["COOLMUSCLE_PURE"] = "1"

    def cli(self, *args: str) -> dict[str, float]:
        """Wall and CPU seconds of ``python -m coolmuscle ARGS`` (stdout discarded)."""
        cpu = _children_cpu()
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "coolmuscle", *args], env=self.env,
                       stdout=subprocess.DEVNULL, check=True)
        return {"wall": time.perf_counter() - start, "cpu": _children_cpu() - cpu}

    def worker(self, *args: str) -> dict[str, float]:
        out = subprocess.run([sys.executable, str(HERE / "speed_worker.py"), *args],
                             env=self.env, capture_output=True, text=True, check=True)
        return json.loads(out.stdout)


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def baseline_tree(ref: str, into: Path) -> Path | None:
    """``ref``'s src/ extracted under ``into`` (None: no git or no such commit)."""
    if ref == "none" or shutil.which("git") is None:
        return None
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", ref, "src"],
                             capture_output=True)
    if archive.returncode != 0:
        return None
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive.stdout, check=True)
    return into


def best(trees: list[Tree], repeat: int,
         measure: Callable[[Tree], dict[str, float]], key: str,
         lower: bool = True) -> list[dict[str, float]]:
    """Each tree's best of ``repeat`` runs (by ``key``), the trees taking turns."""
    found: list[dict[str, float] | None] = [None] * len(trees)
    for _ in range(repeat):
        for i, tree in enumerate(trees):
            got = measure(tree)
            old = found[i]
            if old is None or (got[key] < old[key] if lower else got[key] > old[key]):
                found[i] = got
    return [f for f in found if f is not None]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default=BASELINE, help="git ref of today's tree")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="simulated times / 10")
    opts = parser.parse_args()
    scale = 0.1 if opts.quick else 1.0
    work = Path(tempfile.mkdtemp(prefix="bench_speed_"))
    try:
        return run(opts, scale, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)


#: The issue's table: (row, "today" recorded in the issue, goal, unit, higher is better).
ISSUE = {
    "run1": ("coolmuscle run, 1 motor PTP bank, 10 h", 4_500.0, 10_000.0, "x", True),
    "run15": ("coolmuscle run --motors 15, 600 s", 130.0, 1_000.0, "x", True),
    "chain": ("bench_chain, 15 motors", 327.0, 1_500.0, "x", True),
    "start": ("start of coolmuscle run, one line", 0.65, 0.25, "s", False),
    "move": ("cost per move through a program bank", 200.0, 50.0, "us", False),
    "stream": ("target_stream, 1 ms cycle, per axis-cycle", 330.0, 50.0, "us", False),
}


def run(opts: argparse.Namespace, scale: float, work: Path) -> int:
    trees = [Tree("sources", ROOT, pure=True), Tree("compiled", ROOT)]
    (work / "baseline").mkdir()
    base_root = baseline_tree(opts.baseline, work / "baseline")
    if base_root is not None:
        trees.insert(0, Tree(f"baseline {opts.baseline}", base_root))
    b2 = work / "b2.cml"
    b2.write_text(B2_SCRIPT)
    m15 = work / "m15.cml"
    m15.write_text(chain_script(15))
    one = work / "one.cml"
    one.write_text("?96.1\n")
    for tree in trees:                        # byte-compile, as an installed package is
        tree.cli("run", str(one))
    hours = 36_000 * scale
    rep = opts.repeat
    results: dict[str, list[float]] = {}
    cpu: dict[str, list[float]] = {}           # the same figures from CPU time
    extra: dict[str, list[str]] = {}

    def timed_cli(*args: str) -> Callable[[Tree], dict[str, float]]:
        return lambda tree: tree.cli(*args)

    r = best(trees, rep, timed_cli("run", str(b2), "--until", f"{hours:g}"), "wall")
    results["run1"] = [hours / x["wall"] for x in r]
    cpu["run1"] = [hours / x["cpu"] for x in r]
    r = best(trees, rep, timed_cli("run", str(m15), "--motors", "15", "--until",
                                   f"{600 * scale:g}"), "wall")
    results["run15"] = [600 * scale / x["wall"] for x in r]
    cpu["run15"] = [600 * scale / x["cpu"] for x in r]
    r = best(trees, rep, lambda t: t.worker("chain", "15", f"{60 * scale:g}"), "wall")
    results["chain"] = [x["ratio"] for x in r]
    cpu["chain"] = [60 * scale / x["cpu"] for x in r]
    r = best(trees, max(rep, 5), timed_cli("run", str(one)), "wall")
    results["start"] = [x["wall"] for x in r]
    cpu["start"] = [x["cpu"] for x in r]
    r = best(trees, rep, lambda t: t.worker("moves", f"{2200 * scale:g}"), "wall")
    results["move"] = [x["us_per_move"] for x in r]
    cpu["move"] = [x["cpu_us_per_move"] for x in r]
    extra["move"] = [f"{x['events_per_move']:.2f} events, {x['calls_per_move']:.0f} "
                     f"Python calls a move (CPU {x['cpu_us_per_move']:.0f} us)" for x in r]
    r = best(trees, rep, lambda t: t.worker("stream", "4", f"{round(2000 * scale)}"), "wall")
    results["stream"] = [x["us_per_axis_cycle"] for x in r]
    cpu["stream"] = [x["cpu_us_per_axis_cycle"] for x in r]
    extra["stream"] = [f"{x['calls_per_axis_cycle']:.0f} Python calls, "
                       f"{x['events_per_axis_cycle']:.2f} events an axis-cycle, "
                       f"lag <= {x['max_lag']:.2f} pulses" for x in r]

    names = [t.name for t in trees]
    if len(trees) == 2:
        names.insert(0, "today (issue)")
    print(f"best of {rep} runs each; simulated times x{scale:g}")
    print(f"{'row':44} {names[0]:>18} {names[1]:>12} {names[2]:>12} {'goal':>9}  "
          f"{'gain':>6}  verdict")
    failed = 0
    for key, (label, today, goal, unit, higher) in ISSUE.items():
        values = results[key]
        if len(values) == 2:
            values = [today] + values
        now = values[-1]
        ok = now >= goal if higher else now <= goal
        failed += not ok
        # fmt is used in this iteration only (B023)
        fmt = ((lambda v: f"{v:,.0f}{unit}") if unit in ("x", "us")  # noqa: B023
               else (lambda v: f"{v:.3f} s"))
        gain = now / values[0] if higher else values[0] / now     # compiled vs the first
        print(f"{label:44} {fmt(values[0]):>18} {fmt(values[1]):>12} {fmt(now):>12} "
              f"{fmt(goal):>9}  {gain:>5.2f}x  {'met' if ok else 'NOT met'}")
        by_cpu = cpu[key]
        if len(by_cpu) == 2:
            print(f"{'    the same from CPU time (a loaded machine waits)':44} {'':>18} "
                  f"{fmt(by_cpu[0]):>12} {fmt(by_cpu[1]):>12}")
        else:
            print(f"{'    the same from CPU time (a loaded machine waits)':44} "
                  f"{fmt(by_cpu[0]):>18} {fmt(by_cpu[1]):>12} {fmt(by_cpu[2]):>12}")
        for name, text in zip(names[-len(extra.get(key, [])):], extra.get(key, [])):
            print(f"{'':46}{name}: {text}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
