"""Benchmark: the hand-written CML parser against a lark LALR grammar of CML.

Run: ``PYTHONPATH=src python bench/bench_parser.py`` (about 10 s).  Both parsers
read the same lines, the example lines of the manuals (tests/data/
cml_manual_corpus.txt) that both accept, and the figures are printed side by side
with their ratio.  Each figure is the best of a few timed rounds; building the
lark parser is not timed.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from cml_lark import LarkCml  # noqa: E402

from coolmuscle.cml import format_line, parse  # noqa: E402

CORPUS = ROOT / "tests" / "data" / "cml_manual_corpus.txt"
ROUND_SECONDS = 0.8
ROUNDS = 3


def manual_lines(lark: LarkCml) -> list[str]:
    """The corpus lines (condition fragments made into branches) both parsers accept."""
    texts = []
    for raw in CORPUS.read_text(encoding="utf-8").splitlines():
        if not raw or raw.startswith("#"):
            continue
        _, expect, line = raw.split("\t", 2)
        if expect == "fail":
            continue
        text = line + ", ?99, ?98" if expect == "cond" else line
        if parse(text):
            lark.parse(text)  # must not raise: the comparison is on the same lines
            texts.append(text)
    return texts


def lines_per_second(fn: Callable[[str], object], texts: list[str]) -> float:
    """Best rate over ROUNDS rounds of at least ROUND_SECONDS each."""
    best = 0.0
    for _ in range(ROUNDS):
        count, start = 0, time.perf_counter()
        while True:
            for text in texts:
                fn(text)
            count += len(texts)
            elapsed = time.perf_counter() - start
            if elapsed >= ROUND_SECONDS:
                break
        best = max(best, count / elapsed)
    return best


def round_trip(text: str) -> None:
    for line in parse(text):
        format_line(line)


def main() -> None:
    start = time.perf_counter()
    lark = LarkCml()
    build = time.perf_counter() - start
    texts = manual_lines(lark)
    chars = sum(len(t) for t in texts) / len(texts)
    print(f"corpus: {len(texts)} manual example lines, {chars:.1f} characters on average")
    print(f"lark LALR parser built in {build * 1000:.0f} ms (not timed below)")
    ours = lines_per_second(parse, texts)
    theirs = lines_per_second(lark.parse, texts)
    both = lines_per_second(round_trip, texts)
    print(f"{'parser':<34}{'lines/s':>12}{'us/line':>10}")
    for name, rate in [("coolmuscle.cml.parse", ours), ("lark LALR + transformer", theirs),
                       ("coolmuscle parse + format_line", both)]:
        print(f"{name:<34}{rate:>12,.0f}{1e6 / rate:>10.1f}")
    print(f"ratio hand-written / lark: {ours / theirs:.1f}x")


if __name__ == "__main__":
    main()
