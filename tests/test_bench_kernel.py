"""bench/bench_kernel.py's own check: its naive 1 ms model (a host scanning every
millisecond, the model's physics re-done tick by tick) gives the same trace as the
device at every millisecond of its window, in-position rule (ch. 3 K55) included, so
the benchmark's ratios compare the same work.  Only the check runs here; the timing is
the benchmark's."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

BENCH = Path(__file__).resolve().parents[1] / "bench"


def _bench_kernel() -> ModuleType:
    sys.path.insert(0, str(BENCH))
    try:
        spec = importlib.util.spec_from_file_location("bench_kernel", BENCH / "bench_kernel.py")
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules["bench_kernel"] = module
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCH))
    return module


def test_the_naive_model_traces_what_the_device_does() -> None:
    bench = _bench_kernel()
    assert bench.compare_traces() == bench.WINDOW_S * 1000 + 1
