"""``coolmuscle run --trace`` on long runs.

The trace streams to its file as virtual time passes, with memory that does not
grow with the run; ``--trace-step`` sets the grid; while the motors are at rest
the grid rows are left out (the values hold, exactly); a size warning comes once;
Ctrl-C stops at once and leaves a valid file.  ``run`` as a real subprocess where
signals and wall time matter.
"""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

from coolmuscle.chain.daisy import Chain
from coolmuscle.tools.script.runner import run_script
from coolmuscle.tools.trace.recorder import FIELDS
from fixtures import ChainFactory, wait_until

SRC = str(Path(__file__).resolve().parents[1] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC, "COLUMNS": "300"}
ENV.pop("COOLMUSCLE_DEBUG", None)

MOVES = "S.1=50\nA.1=100\nP.1=2000\n^.1\n@wait 0.6\nP.1=0\n^.1\n@wait 0.6\n"


def read_rows(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def test_a_long_idle_wait_is_fast_small_and_exact(tmp_path: Path) -> None:
    script = tmp_path / "idle.cml"
    script.write_text("S.1=10\nA.1=10\nP.1=100\n^.1\n@wait 100000\n?96.1\n")
    out = tmp_path / "idle.csv"
    start = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "coolmuscle", "run", str(script),
                           "--trace", str(out)], capture_output=True, text=True, env=ENV,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert time.monotonic() - start < 30
    header, rows = read_rows(out)
    assert out.stat().st_size < 5 << 20
    times = [float(r[0]) for r in rows]
    assert times == sorted(times) and times[-1] >= 100000.0
    pos = header.index("m1.position")
    moving = [r for r in rows if float(r[0]) < 1.0]
    assert len(moving) > 500                     # the 1 ms grid while it moves
    assert float(rows[-1][pos]) == 100.0          # and the value held to the end


def test_trace_step_sets_the_grid(tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain()
    run_script(MOVES, chain, trace=tmp_path / "t.csv", trace_step=0.01)
    _, rows = read_rows(tmp_path / "t.csv")
    times = [round(float(r[0]) * 1000) for r in rows]
    on_grid = [t for t in times if t % 10 == 0]
    assert len(on_grid) >= 100 and len(times) < 400


def test_memory_does_not_grow_with_the_run(tmp_path: Path, make_chain: ChainFactory) -> None:
    def peak(repeats: int) -> int:
        chain = make_chain()
        tracemalloc.start()
        run_script(MOVES * repeats, chain, trace=tmp_path / f"m{repeats}.csv", trace_step=0.01)
        _, top = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        chain.close()
        return top
    short, long = peak(10), peak(100)
    assert long < short * 1.5 + (1 << 20), (short, long)
    header, rows = read_rows(tmp_path / "m100.csv")
    assert len(header) == 1 + len(FIELDS) and all(len(r) == len(header) for r in rows)
    assert float(rows[-1][0]) >= 100 * 1.2 - 0.01


def test_a_size_warning_comes_once(tmp_path: Path) -> None:
    warnings: list[str] = []
    run_script(MOVES * 5, Chain(), trace=tmp_path / "w.csv", trace_warn_bytes=50_000,
               on_warning=warnings.append)
    assert len(warnings) == 1 and "w.csv" in warnings[0] and "--trace-step" in warnings[0]


def test_ctrl_c_stops_at_once_and_leaves_a_valid_file(tmp_path: Path) -> None:
    script = tmp_path / "long.cml"
    script.write_text(MOVES * 20000)
    out = tmp_path / "long.csv"
    proc = subprocess.Popen([sys.executable, "-m", "coolmuscle", "run", str(script), "--trace",
                             str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, env=ENV)
    def grown() -> bool:
        return out.exists() and out.stat().st_size >= 100_000
    wait_until(lambda: grown() or proc.poll() is not None, 30, 0.05)
    assert grown() and proc.poll() is None, proc.poll()
    proc.send_signal(signal.SIGINT)
    start = time.monotonic()
    _, stderr = proc.communicate(timeout=20)
    assert time.monotonic() - start < 3
    assert proc.returncode == 130 and "Traceback" not in stderr, stderr
    assert stderr.strip().splitlines()[-1] == "coolmuscle: interrupted"
    header, rows = read_rows(out)
    assert rows and all(len(r) == len(header) for r in rows)
