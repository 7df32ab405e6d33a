"""Speed where users feel it: every row of the table of goals in one run.

Run: ``PYTHONPATH=src python bench/bench_speed.py [--baseline REF] [--repeat N] [--quick]
[--only ROW,...]`` (five to ten minutes; ``--quick`` divides the simulated times by ten;
``--only start`` measures the rows named, keys of :data:`GOALS`; the first run also
builds the baseline's compiled modules, a few minutes, kept in a cache).

The machine of a user is seldom idle, so the bench starts **one competing CPU-bound
process** (a Python busy loop) before it measures anything and stops it at the end
(``--alone``: without it, for comparison only; the goals are judged with it).  It
prints the load average before and after.

Each row is measured on this tree twice, running its sources (``COOLMUSCLE_PURE=1``)
and its compiled hot modules (coolmuscle/_accel.py; build them first with ``python -m
coolmuscle.tools.accel build``), and, side by side in the same run, on the **previous
tree** (``--baseline REF``, default :data:`BASELINE`: main before the goals with a
competing process were worked on), extracted from git into a cache directory and
compiled there as a user's install compiles it (``--baseline-sources``: run it as
sources).  The trees take turns,
``--repeat`` times each, and the best (least disturbed) run of each is shown next to
the goal.  Without git or the commit (``--baseline none``) the baseline column shows
the figure recorded when the goals were set.  Every figure comes from a fresh interpreter (the
``coolmuscle`` command or :mod:`speed_worker`), with byte-compiled modules as an
installed package has them.

Rows (docs/performance.md; * marks the three tightest goals):

1. * ``coolmuscle run`` on a script whose one motor loops a PTP bank of 1.1 s moves,
   10 simulated hours (``--until 36000``): simulated time over the wall time of the
   whole ``coolmuscle`` process (interpreter start, imports, reading the script, the
   simulation, the transcript written to a file), as a user feels it.
2. * ``coolmuscle run --motors 15``, every motor looping its PTP bank, 600 simulated s:
   the same, a process running the installed ``coolmuscle`` command.
2b. ``coolmuscle run --motors 15`` where motor N loops a two-point PTP bank over N x
   1,000 pulses at speed 100 (:func:`ptp_script`), 600 simulated s, its transcript
   captured: many more moves printed than in row 2 (the short moves of the first motors).
3. bench_chain.py's 15-motor chain, 60 simulated s, in process (no start-up).
4. The start of ``coolmuscle run`` on a one-line script (``?96.1``): wall seconds.
5. The cost of one move through a program bank (planner, servo and load model,
   in-position, report, next line), in process, with kernel events and Python calls
   per move.
6. * ``Chain.target_stream`` with a new target every 1 ms on 4 motors (cyclic
   synchronous position of the EtherCAT bridge), in process: wall time per
   axis-cycle.  (The 4-axis bridge in csp, paced to the wall clock, is
   bench_ethercat_csp.py.)
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
from collections.abc import Callable
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
#: main before the goals with a competing process were worked on: the previous tree.
BASELINE = "d0b6843"

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

#: The competing process: one CPU-bound busy loop, as another program on a user's machine.
COMPETITOR = "while True:\n    pass\n"


def ptp_script(motors: int) -> str:
    """Every motor loops a two-point PTP bank (``S1,A1,P1`` / ``P2``) at speed 100, motor
    N over N x 1,000 pulses: short moves on the first motors, so many moves printed."""
    lines = []
    for n in range(1, motors + 1):
        lines.append(f"S1.{n}=100, A1.{n}=100, P1.{n}={1000 * n}, P2.{n}=0")
        lines += [f"B1.{n}", "X0", f"S1.{n}, A1.{n}, P1.{n}", f"P2.{n}", "X-", "END"]
    lines += [f"[1.{n}" for n in range(1, motors + 1)]
    return "\n".join(lines) + "\n"


def chain_script(motors: int) -> str:
    lines = []
    for n in range(1, motors + 1):
        lines.append(f"S1.{n}={100 + n}, A1.{n}=100, P1.{n}=10000, P2.{n}=0")
        lines += [f"B1.{n}", "X0", f"S1.{n}, A1.{n}, P1.{n}", f"P2.{n}", "X-", "END"]
    lines += [f"[1.{n}" for n in range(1, motors + 1)]
    return "\n".join(lines) + "\n"


class Tree:
    """A source tree to measure (its ``src`` on PYTHONPATH, byte code allowed)."""

    def __init__(self, name: str, root: Path, work: Path, *, pure: bool = False) -> None:
        self.name = name
        self.root = root
        self.out = work / f"transcript-{name.replace(' ', '-')}.txt"   # what the run printed
        self.env = dict(os.environ)
        self.env.pop("PYTHONDONTWRITEBYTECODE", None)
        self.env.pop("COOLMUSCLE_PURE", None)
        self.env["PYTHONPATH"] = str(root / "src")
        if pure:                      # the sources, not the compiled modules (_accel.py)
            self.env["COOLMUSCLE_PURE"] = "1"
        # The installed command (pyproject's [project.scripts]), when this tree has it.
        if (root / "src/coolmuscle/tools/cli/entry.py").exists():
            self.command = [sys.executable, "-c", "import sys; from coolmuscle.tools.cli."
                            "entry import main; sys.argv[0] = 'coolmuscle'; sys.exit(main())"]
        else:
            self.command = [sys.executable, "-m", "coolmuscle"]

    def cli(self, *args: str) -> dict[str, float]:
        """Wall and CPU seconds of the ``coolmuscle ARGS`` process, its transcript
        written to a file."""
        cpu = _children_cpu()
        start = time.perf_counter()
        with open(self.out, "wb") as out:
            subprocess.run([*self.command, *args], env=self.env, stdout=out, check=True)
        return {"wall": time.perf_counter() - start, "cpu": _children_cpu() - cpu}

    def worker(self, *args: str) -> dict[str, float]:
        out = subprocess.run([sys.executable, str(HERE / "speed_worker.py"), *args],
                             env=self.env, capture_output=True, text=True, check=True)
        got: dict[str, float] = json.loads(out.stdout)
        return got


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "?"


def baseline_tree(ref: str, compiled: bool) -> tuple[Path | None, str]:
    """``ref``'s src/, extracted once into a cache directory and, when ``compiled``,
    with its hot modules compiled there (as a user's install builds them); None
    without git or the commit.  The note says what the column runs."""
    if ref == "none" or shutil.which("git") is None:
        return None, ""
    sha = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", f"{ref}^{{commit}}"],
                         capture_output=True, text=True)
    if sha.returncode != 0:
        return None, ""
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    into = cache / "coolmuscle-bench" / sha.stdout.strip()
    if not (into / "src" / "coolmuscle").is_dir():
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", ref, "src"],
                                 capture_output=True, check=True)
        into.mkdir(parents=True, exist_ok=True)
        subprocess.run(["tar", "-x", "-C", str(into)], input=archive.stdout, check=True)
    if not compiled:
        return into, "sources"
    if not (into / "src/coolmuscle/_accel.py").exists():
        return into, "sources (no compiled modules then)"
    env = dict(os.environ, PYTHONPATH=str(into / "src"))
    env.pop("COOLMUSCLE_PURE", None)
    print(f"{ref}: its compiled hot modules in {into} (built on first use, then kept)",
          flush=True)
    built = subprocess.run([sys.executable, "-m", "coolmuscle.tools.accel", "build", "--quiet"],
                           env=env, cwd=into)
    return into, "compiled" if built.returncode == 0 else "sources (its build failed)"


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
    parser.add_argument("--baseline", default=BASELINE, help="git ref of the previous tree")
    parser.add_argument("--baseline-sources", action="store_true",
                        help="run the previous tree as sources (no compiled modules)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="simulated times / 10")
    parser.add_argument("--alone", action="store_true",
                        help="no competing process (for comparison; goals are judged with it)")
    parser.add_argument("--only", default=",".join(GOALS),
                        help=f"the rows to measure, comma-separated ({', '.join(GOALS)})")
    opts = parser.parse_args()
    unknown = set(opts.only.split(",")) - set(GOALS)
    if unknown:
        parser.error(f"--only: unknown row {sorted(unknown)[0]!r}")
    scale = 0.1 if opts.quick else 1.0
    work = Path(tempfile.mkdtemp(prefix="bench_speed_"))
    competitor = None
    try:
        base_root, note = baseline_tree(opts.baseline, not opts.baseline_sources)
        load = _load()
        if not opts.alone:
            competitor = subprocess.Popen([sys.executable, "-c", COMPETITOR])
        return run(opts, scale, work, base_root, note, load)
    finally:
        if competitor is not None:
            competitor.kill()
            competitor.wait()
        shutil.rmtree(work, ignore_errors=True)


#: Each row: (label, recorded when the goals were set, goal, unit, higher is better, one
#: of the tightest goals).
GOALS = {
    "run1": ("coolmuscle run, 1 motor PTP bank, 10 h", 4_500.0, 10_000.0, "x", True, True),
    "run15": ("coolmuscle run --motors 15, 600 s", 130.0, 1_000.0, "x", True, True),
    "run15ptp": ("coolmuscle run --motors 15, 1,000-15,000 pulses", 840.0, 1_000.0, "x",
                 True, True),
    "chain": ("bench_chain, 15 motors, in process", 327.0, 1_500.0, "x", True, False),
    "start": ("start of coolmuscle run, one line", 0.65, 0.25, "s", False, False),
    "move": ("cost per move through a program bank", 200.0, 50.0, "us", False, False),
    "stream": ("target_stream, 1 ms cycle, per axis-cycle", 330.0, 50.0, "us", False, True),
}


def _formatter(unit: str) -> Callable[[float], str]:
    if unit in ("x", "us"):
        return lambda v: f"{v:,.0f}{unit}"
    return lambda v: f"{v:.3f} s"


def run(opts: argparse.Namespace, scale: float, work: Path, base_root: Path | None,
        note: str, load: str) -> int:
    trees = [Tree("sources", ROOT, work, pure=True), Tree("compiled", ROOT, work)]
    if base_root is not None:
        trees.insert(0, Tree(f"previous {opts.baseline}", base_root, work))
    b2 = work / "b2.cml"
    b2.write_text(B2_SCRIPT)
    m15 = work / "m15.cml"
    m15.write_text(chain_script(15))
    ptp15 = work / "ptp15.cml"
    ptp15.write_text(ptp_script(15))
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

    rows = opts.only.split(",")
    if "run1" in rows:
        r = best(trees, rep, timed_cli("run", str(b2), "--until", f"{hours:g}"), "wall")
        results["run1"] = [hours / x["wall"] for x in r]
        cpu["run1"] = [hours / x["cpu"] for x in r]
    if "run15" in rows:
        r = best(trees, rep, timed_cli("run", str(m15), "--motors", "15", "--until",
                                       f"{600 * scale:g}"), "wall")
        results["run15"] = [600 * scale / x["wall"] for x in r]
        cpu["run15"] = [600 * scale / x["cpu"] for x in r]
    if "run15ptp" in rows:
        r = best(trees, rep, timed_cli("run", str(ptp15), "--motors", "15", "--until",
                                       f"{600 * scale:g}"), "wall")
        results["run15ptp"] = [600 * scale / x["wall"] for x in r]
        cpu["run15ptp"] = [600 * scale / x["cpu"] for x in r]
    if "chain" in rows:
        r = best(trees, rep, lambda t: t.worker("chain", "15", f"{60 * scale:g}"), "wall")
        results["chain"] = [x["ratio"] for x in r]
        cpu["chain"] = [60 * scale / x["cpu"] for x in r]
    if "start" in rows:
        r = best(trees, max(rep, 5), timed_cli("run", str(one)), "wall")
        results["start"] = [x["wall"] for x in r]
        cpu["start"] = [x["cpu"] for x in r]
    if "move" in rows:
        r = best(trees, rep, lambda t: t.worker("moves", f"{2200 * scale:g}"), "wall")
        results["move"] = [x["us_per_move"] for x in r]
        cpu["move"] = [x["cpu_us_per_move"] for x in r]
        extra["move"] = [f"{x['events_per_move']:.2f} events, {x['calls_per_move']:.0f} "
                         f"Python calls a move (CPU {x['cpu_us_per_move']:.0f} us)" for x in r]
    if "stream" in rows:
        r = best(trees, rep, lambda t: t.worker("stream", "4", f"{round(2000 * scale)}"),
                 "wall")
        results["stream"] = [x["us_per_axis_cycle"] for x in r]
        cpu["stream"] = [x["cpu_us_per_axis_cycle"] for x in r]
        extra["stream"] = [f"{x['calls_per_axis_cycle']:.0f} Python calls, "
                           f"{x['events_per_axis_cycle']:.2f} events an axis-cycle, "
                           f"lag <= {x['max_lag']:.2f} pulses" for x in r]

    names = [t.name for t in trees]
    if len(trees) == 2:
        names.insert(0, "when the goals were set")
    competing = "alone (--alone)" if opts.alone else "one competing CPU-bound process running"
    print(f"best of {rep} runs each; simulated times x{scale:g}; {competing}; "
          f"load average {load} before, {_load()} after")
    if note:
        print(f"{names[0]}: {note}; gain = this tree compiled / {names[0]}")
    print(f"{'row (* the tightest goals)':46} {names[0]:>18} {names[1]:>12} {names[2]:>12} "
          f"{'goal':>9}  {'gain':>6}  verdict")
    failed = 0
    for key, (label, today, goal, unit, higher, open_) in GOALS.items():
        if key not in results:
            continue
        values = results[key]
        if len(values) == 2:
            values = [today] + values
        now = values[-1]
        ok = now >= goal if higher else now <= goal
        failed += not ok
        fmt = _formatter(unit)
        gain = now / values[0] if higher else values[0] / now     # compiled vs the first
        mark = "* " if open_ else "  "
        print(f"{mark + label:46} {fmt(values[0]):>18} {fmt(values[1]):>12} {fmt(now):>12} "
              f"{fmt(goal):>9}  {gain:>5.2f}x  {'met' if ok else 'NOT met'}")
        by_cpu = cpu[key]
        if len(by_cpu) == 2:
            print(f"{'      the same from CPU time':46} {'':>18} "
                  f"{fmt(by_cpu[0]):>12} {fmt(by_cpu[1]):>12}")
        else:
            print(f"{'      the same from CPU time':46} "
                  f"{fmt(by_cpu[0]):>18} {fmt(by_cpu[1]):>12} {fmt(by_cpu[2]):>12}")
        notes = extra.get(key, [])
        for name, text in zip(names[-len(notes):], notes, strict=True) if notes else ():
            print(f"{'':48}{name}: {text}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
