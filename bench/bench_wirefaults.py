"""Benchmark: a wire-fault storm for minutes (docs/wire-faults.md, docs/reliability.md).

Faults of every door rain on a served chain (the TCP host line, Modbus TCP, the CM1
EtherNet/IP module; tests/storm_support.py) while the host library, pymodbus and pycomm3
keep talking to it and motor 2 is saved and power cycled over and over.  Printed: the
resident memory at the start, at each sample (the middle, the end), the exchanges and
typed errors of each peer, and the counts that must stay 0 (tracebacks, unexpected
exceptions in a peer, saved data lost, front-end failures).  tests/test_wire_faults_storm.py
runs 20 s of it.

::

    PYTHONPATH=src python bench/bench_wirefaults.py [--minutes 10] [--samples 10]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from storm_support import storm  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--samples", type=int, default=10)
    options = parser.parse_args()
    seconds = options.minutes * 60

    def sample(elapsed: float, mib: float) -> None:
        print(f"  {elapsed:7.0f} s  RSS {mib:6.1f} MiB", flush=True)

    print(f"wire-fault storm, {options.minutes:g} min", flush=True)
    report = storm(seconds, samples=options.samples, on_sample=sample)
    start, middle, end = report.rss[0][1], report.rss[len(report.rss) // 2][1], \
        report.rss[-1][1]
    print(f"RSS start {start:.1f} MiB, middle {middle:.1f} MiB, end {end:.1f} MiB "
          f"(end - middle {end - middle:+.1f} MiB)")
    print(report.summary())
    for line in report.problems():
        print("  !", line)
    print("clean" if report.clean else "NOT CLEAN")
    sys.exit(0 if report.clean else 1)


if __name__ == "__main__":
    main()
