"""Batch benchmark: 200 scripts through ``coolmuscle batch`` with 1 and 2 jobs and Dask.

Run: ``PYTHONPATH=src python bench/bench_batch.py [--count N] [--figures]`` (about a
minute for 200; ``--count 40`` for a quick look).

The scripts are the golden transcripts of tests/transcripts/ (the manual's examples,
checked byte for byte), repeated to COUNT files.  Each configuration runs the whole
batch as a user does, ``coolmuscle batch DIR ...`` in a fresh process, and is timed
from start to exit:

* ``-j 1``: the runs one after another in the command's own process;
* ``-j 2``: a local process pool of two;
* ``dask``: a ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1
  (started before the timing, stopped after), ``--scheduler``.

Printed side by side: the wall time, the speed-up over ``-j 1`` next to the ideal
(the jobs, at most the CPUs this process may use), the same for the cost per run
(start-up left out), and the cost per run
((batch of COUNT - batch of two ``?96.1``) / (COUNT - 2)) next to one ``coolmuscle run --check``
of a script (a fresh process each time: what a shell loop over the scripts costs) and
next to the run itself in a warm process (``execute`` of the job, no command around
it).  ``--figures`` adds ``--results`` (each run then also computes its figures from
the trace, docs/batch.md), which gives the workers more to do per run.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / "src"
TRANSCRIPTS = ROOT / "tests" / "transcripts"
ENV = dict(os.environ, PYTHONPATH=str(SRC))

sys.path.insert(0, str(ROOT / "tests"))
from dask_support import dask_cluster  # noqa: E402


def make_scripts(folder: Path, count: int) -> list[Path]:
    """COUNT scripts: the golden transcripts repeated (machine files copied beside)."""
    sources = sorted(TRANSCRIPTS.glob("*.cml"))
    for sub in ("machines",):
        if (TRANSCRIPTS / sub).is_dir():
            shutil.copytree(TRANSCRIPTS / sub, folder / sub, dirs_exist_ok=True)
    paths = []
    for i in range(count):
        source = sources[i % len(sources)]
        path = folder / f"{i:04d}-{source.name}"
        path.write_text(source.read_text(encoding="utf-8"), encoding="utf-8")
        paths.append(path)
    return paths


def timed(args: list[str]) -> float:
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "coolmuscle", *args], env=ENV,
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"coolmuscle {' '.join(args[:3])} ... failed ({proc.returncode}): "
                         f"{proc.stderr.strip().splitlines()[-1:]}")
    return wall


def warm_run_cost(paths: list[Path], figures: bool) -> float:
    """Seconds per run of ``execute`` in this (warm) process: the work itself."""
    sys.path.insert(0, str(SRC))
    from coolmuscle.tools.batch.job import execute, make_job

    jobs = [make_job(str(p), p.read_text(encoding="utf-8"), p.parent, figures=figures)
            for p in paths]
    execute(jobs[0])
    start = time.perf_counter()
    for job in jobs:
        execute(job)
    return (time.perf_counter() - start) / len(jobs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=200, help="scripts (default 200)")
    parser.add_argument("--figures", action="store_true",
                        help="also write --results (figures from each run's trace)")
    parser.add_argument("--no-dask", action="store_true", help="skip the Dask cluster")
    parser.add_argument("--repeats", type=int, default=2,
                        help="best of this many runs of each batch (default 2)")
    options = parser.parse_args()
    count = max(options.count, 3)
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp:
        folder = Path(tmp)
        many, one = folder / "many", folder / "one"
        many.mkdir()
        one.mkdir()
        paths = make_scripts(many, count)
        for name in ("a", "b"):  # the batch of 2 (a pool of 2 too): start-up cost only
            (one / f"{name}.cml").write_text("?96.1\n")
        extra = ["--results", str(folder / "r.csv")] if options.figures else []

        work = min(warm_run_cost(paths[:min(count, 61)], options.figures)
                   for _ in range(max(options.repeats, 1)))
        plain = [p for p in paths if "# chain:" not in p.read_text(encoding="utf-8")]
        singles = [timed(["run", str(p), "--check"]) for p in plain[:5]]  # `run` reads
        # no '# chain:' header: those need --motors etc.
        single = min(singles)
        rows: list[tuple[str, int, float, float]] = []
        configs: list[tuple[str, list[str], int]] = [("-j 1", ["--jobs", "1"], 1),
                                                     ("-j 2", ["--jobs", "2"], 2)]
        with contextlib.ExitStack() as stack:
            if not options.no_dask:
                try:
                    address = stack.enter_context(dask_cluster(folder, 2, ENV))
                except RuntimeError as exc:
                    raise SystemExit(str(exc)) from None
                configs.append(("dask, 2 workers", ["--scheduler", address], 2))
            # round after round of every configuration, so a busy moment of the shared
            # machine falls on all of them alike; the best of the rounds counts
            fulls = {label: float("inf") for label, _, _ in configs}
            bases = dict(fulls)
            for _ in range(max(options.repeats, 1)):
                for label, args, _ in configs:
                    fulls[label] = min(fulls[label],
                                       timed(["batch", str(many), *args, *extra]))
                    bases[label] = min(bases[label], timed(["batch", str(one), *args, *extra]))
            for label, _, jobs in configs:
                rows.append((label, jobs, fulls[label],
                             (fulls[label] - bases[label]) / (count - 2)))

    print(f"{count} scripts (tests/transcripts repeated), {cpus} CPU(s)"
          f"{', with figures (--results)' if options.figures else ''}")
    print(f"one `coolmuscle run --check` (fresh process): {single * 1000:8.1f} ms; "
          f"the run itself, warm: {work * 1000:6.2f} ms")
    print(f"{'engine':<16} {'wall s':>8} {'speed-up':>9} {'ideal':>6} "
          f"{'ms per run':>11} {'per-run x':>10} {'vs one run':>11} {'vs the work':>12}")
    serial, serial_run = rows[0][2], rows[0][3]
    for label, jobs, full, per_run in rows:
        ideal = min(jobs, cpus or 1)
        print(f"{label:<16} {full:8.2f} {serial / full:8.2f}x {ideal:5d}x "
              f"{per_run * 1000:11.2f} {serial_run / per_run:9.2f}x "
              f"{single / per_run:10.1f}x {per_run / work:11.2f}x")
    print("speed-up: wall of -j 1 / wall; ms per run: (batch of COUNT - batch of two ?96.1) / "
          "(COUNT - 2), per-run x: -j 1's / this one's (the speed-up less the start-up); "
          "vs one run: how many runs a batch makes in the time of one `coolmuscle run`; "
          "vs the work: batch cost per run / the run's own cost")


if __name__ == "__main__":
    main()
