"""The dashboard's host tools: banks from the page and its traces (docs/web.md).

:class:`DashboardTools` implements :class:`coolmuscle.frontends.web.toolbox.Toolbox`;
:class:`WebDashboard` is the web transport with it (the ``web`` transport of the
registry, ``coolmuscle sim --web``).

Banks: list, check, upload and read back (2.2.2, 2.2.3, 6.6 ``?1000``).

An upload is what a terminal program does on the host line, done in one step of the
model's loop: the text is checked first by ``coolmuscle check``'s checker (a text with
errors is not sent; each error names its line), then every line goes to
``Device.execute(origin="web")`` (bank headers, bodies and ``END`` as typed), and every
bank is read back with ``?#.n`` / ``?L#.n`` and compared in canonical form
(:func:`coolmuscle.client.banks.compare_bank`), as ``coolmuscle upload`` verifies.
Because the whole upload runs in one call, a page closed during an upload leaves the
banks either as they were (the request never arrived whole) or fully written.
"""

from __future__ import annotations

import csv
import importlib
import math
import threading
from pathlib import Path
from typing import Any, Iterator

from ...client.banks import compare_bank, parse_bank_listing
from ...client.program import BankBlock, parse_program
from .server import WebTransport
from .toolbox import Note
from ..check.lint import check_program


def list_banks(device: Any, motor: int) -> dict[str, Any]:
    """Every bank of ``motor`` as ``?1000.n`` lists them (6.6), and its summary line."""
    lines = device.execute(f"?1000.{motor}", origin="web", motor=motor)
    banks = parse_bank_listing(lines, motor)
    summary = [line for line in lines if line.startswith("Commands")]
    return {"banks": [{"label": label, "lines": body} for label, body in banks.items()],
            "summary": summary[0] if summary else ""}


def _firmware(device: Any) -> str:
    firmware = getattr(device, "firmware", None)
    return str(getattr(firmware, "name", "cm2"))


def check_text(device: Any, motor: int, text: str) -> tuple[Any, list[dict[str, Any]]]:
    """Parse and check ``text``; diagnostics as ``{line, column, severity, message}``."""
    program = parse_program(text, "<page>")
    report = check_program(program, firmware=_firmware(device), motors=len(device.motor_ids))
    found = [{"line": d.line, "column": d.column, "severity": d.severity, "rule": d.rule,
              "message": d.message + (f" (error{d.motor_error:02d})"
                                      if d.motor_error is not None else "")}
             for d in report.diagnostics]
    return program, found


def upload_banks(device: Any, motor: int, text: str, note: Note) -> dict[str, Any]:
    """Check, send and read back ``text``; bank headers without ``.n`` go to ``motor``."""
    program, diagnostics = check_text(device, motor, text)
    if any(d["severity"] == "error" for d in diagnostics):
        return {"uploaded": False, "diagnostics": diagnostics, "differences": []}
    if not program.banks:
        return {"uploaded": False, "diagnostics": diagnostics + [{
            "line": 1, "column": 1, "severity": "error", "rule": "no-bank",
            "message": "no bank here: a bank starts with B#.n or L#.n and ends with END"}],
            "differences": []}
    device.execute("", origin="web", motor=motor)   # end a bank half typed in the console
    for item in program.items:
        sends = item.send_lines() if isinstance(item, BankBlock) else [item.send]
        for line in sends:
            if line:
                note([device.kernel.now, ">", line, motor, "web"])
            device.execute(line, origin="web", motor=motor)
    differences = []
    for block in program.banks:
        if block.motor is None:
            block.motor = motor
        query = f"?{'L' if block.ladder else ''}{block.number}.{block.motor_id}"
        got = device.execute(query, origin="web", motor=motor)
        differences += [d.format() for d in compare_bank(block, got)]
    return {"uploaded": True, "diagnostics": diagnostics, "differences": differences,
            "banks": [b.label for b in program.banks]}


class DashboardTools:
    """The host tools the dashboard uses (:class:`~coolmuscle.frontends.web.toolbox.Toolbox`)."""

    def list_banks(self, device: Any, motor: int) -> dict[str, Any]:
        return list_banks(device, motor)

    def upload_banks(self, device: Any, motor: int, text: str, note: Note) -> dict[str, Any]:
        return upload_banks(device, motor, text, note)

    def start_recording(self, device: Any) -> Any:
        from ..trace.recorder import NoTraceRecorderError, record
        try:
            recorder = record(device)
        except NoTraceRecorderError:
            return None
        # matplotlib takes seconds to import: do it now, beside the loop, not at the
        # first plot request (which runs in the model's thread).  Not a daemon: a
        # daemon thread stopped at exit inside matplotlib's C++ extensions (Ctrl-C
        # right after the start) aborts the process ("terminate called without an
        # active exception", SIGABRT); the exit waits for the import instead.
        threading.Thread(target=importlib.import_module, args=("coolmuscle.tools.trace.plot",),
                         name="coolmuscle-web-plot-import", daemon=False).start()
        return recorder

    def parquet_available(self) -> bool:
        from ..trace.recorder import parquet_available
        return parquet_available()

    def trace_rows(self, recorder: Any, step: float, end: int) -> tuple[list[str], Iterator[Any]]:
        return recorder.header(), iter(recorder.rows(step, end))

    def write_rows(self, path: Path, header: list[str], rows: list[list[float]]) -> None:
        """CSV as ``coolmuscle run --trace`` writes it, or Parquet (typed columns)."""
        if path.suffix == ".parquet":
            _write_parquet(path, header, rows)
            return
        with path.open("w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(header)
            for row in rows:
                writer.writerow([f"{row[0]:.9f}"] + [_cell(v) for v in row[1:]])

    def plot(self, device: Any, path: Path, title: str) -> None:
        from ..trace.plot import plot
        plot(device, path, title=title)


def _cell(value: float) -> str:
    """Integers without a point, infinities as ``inf``, others to 6 decimals."""
    if isinstance(value, float) and not math.isfinite(value):
        return "inf" if value > 0 else "-inf"
    if float(value).is_integer() and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.6f}"


def _write_parquet(path: Path, header: list[str], rows: list[list[float]]) -> None:
    import pyarrow as pa  # noqa: PLC0415  (optional)
    import pyarrow.parquet as pq  # noqa: PLC0415

    from ..trace.recorder import INTEGER_FIELDS
    columns = list(zip(*rows)) if rows else [() for _ in header]
    arrays = {}
    for name, values in zip(header, columns):
        if name.rsplit(".", 1)[-1] in INTEGER_FIELDS:
            arrays[name] = pa.array([int(v) for v in values], type=pa.int64())
        else:
            arrays[name] = pa.array([float(v) for v in values], type=pa.float64())
    pq.write_table(pa.table(arrays), str(path))


class WebDashboard(WebTransport):
    """The web dashboard transport with the host tools (banks, traces, plots)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8080, **options: Any) -> None:
        options.setdefault("toolbox", DashboardTools())
        super().__init__(host, port, **options)
