"""The page's downloads: the recorded trace (CSV / Parquet) and its plot (PNG).

The trace is sampled from the recorder in the model's thread a few hundred rows at a
time, between which the simulator runs on (virtual time keeps pace with the wall clock),
up to the instant of the request; the file is then written from those rows in a worker
thread, which touches no model state.  The plot is sampled the same way, a few hundred
samples a turn, and drawn in a worker thread from what was sampled (matplotlib never
runs in the event loop).  One download is prepared at a time; another request
meanwhile gets 429.  Who may download is the server's check (:mod:`.access`: a request
from another site is refused).
"""

from __future__ import annotations

import asyncio
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ...frontends.transports.base import Port
from ...needs import has_extra, needs_extra
from ..trace.recorder import TraceRecorder, parquet_available
from .traces import draw, plot_facts, plot_times, sample_motors, trace_rows, write_rows
from .turns import in_worker

with needs_extra("web", "the web page"):
    from aiohttp import web

#: Most samples (rows x motors) of one downloaded trace: the step grows for long
#: recordings (at least 1 ms, the step of ``coolmuscle run --trace``).
MAX_TRACE_SAMPLES = 600_000
#: Rows sampled in one turn of the model's loop.
ROWS_PER_TURN = 400
#: Samples (instants x motors) of a plot taken in one turn of the model's loop.
SAMPLES_PER_TURN = 400

_TYPES = {"csv": "text/csv", "parquet": "application/vnd.apache.parquet", "png": "image/png"}


class Downloads:
    """``/api/trace.{csv,parquet}`` and ``/api/plot.png`` of one dashboard."""

    def __init__(self, port: Port, recorder: Callable[[], TraceRecorder | None],
                 title: str = "") -> None:
        self.port = port
        self._recorder = recorder
        self.title = title
        self._busy = asyncio.Lock()

    def _refusal(self) -> web.Response | None:
        if self._recorder() is None:
            return _error(409, "nothing recorded: press Record first")
        if self._busy.locked():
            return _error(429, "a download is being prepared; try again in a moment")
        return None

    async def trace(self, request: web.Request) -> web.StreamResponse:
        fmt = request.match_info["fmt"]
        refused = self._refusal()
        if refused is not None:
            return refused
        if fmt == "parquet" and not parquet_available():
            return _error(409, "Parquet needs pyarrow (pip install pyarrow); CSV works")
        async with self._busy:
            header, rows = await self._sample()
            body = await in_worker(self._write, f"trace.{fmt}", header, rows)
        return _file(f"trace.{fmt}", body)

    async def _sample(self) -> tuple[list[str], list[list[float]]]:
        recorder = self._recorder()
        assert recorder is not None
        end = recorder.chain.kernel.now
        span = max(end - recorder.start, 0) / 1e9
        motors = max(len(recorder.motor_ids), 1)
        step = max(0.001, span * motors / MAX_TRACE_SAMPLES)
        header, source = self.port.call(trace_rows, recorder, step, end)
        rows: list[list[float]] = []
        while True:
            chunk = self.port.call(_take, source, ROWS_PER_TURN)
            rows += chunk
            if len(chunk) < ROWS_PER_TURN:
                return header, rows
            await asyncio.sleep(0)

    @staticmethod
    def _write(name: str, header: list[str], rows: list[list[float]]) -> bytes:
        with tempfile.TemporaryDirectory(prefix="coolmuscle-web-") as tmp:
            path = Path(tmp) / name
            write_rows(path, header, rows)
            return path.read_bytes()

    async def plot(self, _request: web.Request) -> web.StreamResponse:
        refused = self._refusal()
        if refused is not None:
            return refused
        if not has_extra("plot"):
            return _error(409, 'the plot needs the \'plot\' extra: pip install '
                               '"coolmuscle[plot]"; the trace (CSV) works')
        recorder = self._recorder()
        assert recorder is not None
        async with self._busy:
            times = self.port.call(plot_times, recorder)
            step = max(1, SAMPLES_PER_TURN // max(len(recorder.motor_ids), 1))
            samples: dict[int, list[Any]] = {}
            for at in range(0, len(times), step):
                part = self.port.call(sample_motors, recorder, times[at:at + step])
                for motor, values in part.items():
                    samples.setdefault(motor, []).extend(values)
                await asyncio.sleep(0)         # the others' turn between two slices
            facts = self.port.call(plot_facts, recorder, times, samples)
            body = await in_worker(draw, facts, self.title)
        return _file("plot.png", body)


def _take(rows: Iterator[list[float]], count: int) -> list[list[float]]:
    out = []
    for row in rows:
        out.append(row)
        if len(out) >= count:
            break
    return out


def _file(name: str, body: bytes) -> web.Response:
    return web.Response(body=body, content_type=_TYPES[name.rsplit(".", 1)[1]], headers={
        "Content-Disposition": f'attachment; filename="coolmuscle-{name}"'})


def _error(status: int, message: str) -> web.Response:
    return web.json_response({"error": message}, status=status)
