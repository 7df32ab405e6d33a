"""What the dashboard needs from the host tools, as a protocol (the layers: docs/architecture.md).

The front end owns the page, the feed and the requests; banks (check, upload, read
back) and traces (record, CSV/Parquet, plot) are host tools of a higher layer
(``coolmuscle check``'s checker, the client's bank verification, the trace recorder).
:class:`coolmuscle.tools.web.dashboard.DashboardTools` implements this protocol and
:class:`coolmuscle.tools.web.dashboard.WebDashboard` is the transport with it; a bare
:class:`~.server.WebTransport` without a toolbox answers those requests with a clear
"not available" message.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Iterator, Protocol

#: Adds a line ``[time_ns, kind, text, motor, origin]`` to every page's console log.
Note = Callable[[list[Any]], None]


class Toolbox(Protocol):
    """Bank and trace services; every method runs in the model's thread (Port.call)."""

    def list_banks(self, device: Any, motor: int) -> dict[str, Any]:
        """``{"banks": [{"label", "lines"}], "summary": "Commands.n: ..."}`` (6.6 ?1000)."""

    def upload_banks(self, device: Any, motor: int, text: str, note: Note) -> dict[str, Any]:
        """Check, send and read back ``text``: ``{"uploaded", "diagnostics", ...}``."""

    def start_recording(self, device: Any) -> Any:
        """The chain's trace recorder from now on, or None when it has none."""

    def parquet_available(self) -> bool:
        """Whether Parquet traces can be written (pyarrow)."""

    def trace_rows(self, recorder: Any, step: float, end: int) -> tuple[list[str], Iterator[Any]]:
        """The trace's column names and its rows up to ``end`` (ns), drawn lazily: the
        caller takes a few at a time in the model's thread."""

    def write_rows(self, path: Path, header: list[str], rows: list[list[float]]) -> None:
        """Write sampled rows to ``path`` (CSV, or Parquet for .parquet); any thread."""

    def plot(self, device: Any, path: Path, title: str) -> None:
        """Plot what the chain's recorder holds into ``path`` (PNG)."""
