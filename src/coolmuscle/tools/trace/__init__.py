"""Traces of a chain and their plots (docs/plots.md).

* :mod:`.recorder` - the trace recorder (closed-form motion sampled without ticking),
  streamed to CSV or Parquet as the run goes;
* :mod:`.plot` - matplotlib plots of a trace (imported on its own: it loads matplotlib).

``from coolmuscle.tools.trace import record, trace``; ``from coolmuscle.tools.trace.plot
import plot``.
"""

from __future__ import annotations

from .recorder import FIELDS, Sample, TraceFormatError, TraceRecorder, record, trace

__all__ = ["FIELDS", "Sample", "TraceFormatError", "TraceRecorder", "record", "trace"]
