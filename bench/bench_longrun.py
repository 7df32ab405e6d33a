"""Long runs: the memory of ``coolmuscle run`` after 1, 10 and 100 simulated hours.

Run: ``PYTHONPATH=src python bench/bench_longrun.py [--baseline REF] [--long]`` (a few
minutes; ``--long`` adds 100 hours of 15 motors, several minutes more).

Each run is the ``coolmuscle`` command in a fresh interpreter, as a user runs it, its
transcript written to a file as it goes (every move of every motor is a line): one
motor looping a PTP bank of 1.1 s moves (bench_speed.py's first row), and 15 motors
each looping its own (bench_speed.py's second row), with ``--until`` the hours asked.
The figure is the peak resident memory of that process (``ru_maxrss`` of the child,
from ``os.wait4``), printed side by side for each length of run and for the previous
tree (``--baseline REF``, default :data:`BASELINE`, extracted and compiled as
bench_speed.py does) beside this one.  A run whose memory does not grow with its
length shows the same figure in every column.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_speed import B2_SCRIPT, ROOT, Tree, baseline_tree, chain_script  # noqa: E402

#: main when the growth was found (then: 107 MiB after 100 h with one motor,
#: 159 MiB after 10 h with 15 motors), before ``coolmuscle run`` streamed its transcript.
BASELINE = "5c722ef"
HOURS = (1, 10, 100)


def peak_rss(tree: Tree, script: Path, hours: float, motors: int) -> tuple[float, float, int]:
    """Peak RSS (MiB), wall seconds and transcript bytes of ``coolmuscle run``."""
    args = [*tree.command, "run", str(script), "--until", f"{hours * 3600:g}"]
    if motors > 1:
        args += ["--motors", str(motors)]
    start = time.perf_counter()
    with open(tree.out, "wb") as out:
        child = subprocess.Popen(args, env=tree.env, stdout=out)
        _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        raise SystemExit(f"{tree.name}: coolmuscle run exited {child.returncode}")
    return usage.ru_maxrss / 1024, wall, tree.out.stat().st_size


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default=BASELINE, help="git ref of the previous tree")
    parser.add_argument("--long", action="store_true", help="15 motors for 100 h too")
    opts = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="coolmuscle-longrun-"))
    try:
        trees = [Tree("this tree", ROOT, work)]
        base, note = baseline_tree(opts.baseline, compiled=True)
        if base is not None:
            trees.insert(0, Tree(f"{opts.baseline} ({note})", base, work))
        one, fifteen = work / "one.cml", work / "fifteen.cml"
        one.write_text(B2_SCRIPT, encoding="utf-8")
        fifteen.write_text(chain_script(15), encoding="utf-8")
        rows = [(1, one, HOURS), (15, fifteen, HOURS if opts.long else HOURS[:2])]
        print(f"peak RSS of coolmuscle run (MiB), its transcript written to a file; "
              f"load average {os.getloadavg()[0]:.1f}")
        print(f"{'tree':32} {'motors':>6} " + "".join(f"{f'{h} h':>10}" for h in HOURS)
              + f"{'wall (longest)':>16} {'transcript':>12}")
        for motors, script, hours in rows:
            for tree in trees:
                found = [peak_rss(tree, script, h, motors) for h in hours]
                cells = "".join(f"{rss:>10.1f}" for rss, _, _ in found)
                cells += " " * 10 * (len(HOURS) - len(hours))
                _, wall, size = found[-1]
                print(f"{tree.name[:32]:32} {motors:>6} {cells}{wall:>14.1f} s "
                      f"{size / 2**20:>9.1f} MiB", flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
