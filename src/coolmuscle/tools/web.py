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

from pathlib import Path
from typing import Any

from ..client.banks import compare_bank, parse_bank_listing
from ..client.program import BankBlock, parse_program
from ..frontends.web.server import WebTransport
from ..frontends.web.toolbox import Note
from .check import check_program


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
        from .trace import NoTraceRecorderError, record
        try:
            return record(device)
        except NoTraceRecorderError:
            return None

    def parquet_available(self) -> bool:
        from .trace import parquet_available
        return parquet_available()

    def write_trace(self, recorder: Any, path: Path, step: float) -> None:
        recorder.write(path, step=step)

    def plot(self, device: Any, path: Path, title: str) -> None:
        from .plot import plot
        plot(device, path, title=title)


class WebDashboard(WebTransport):
    """The web dashboard transport with the host tools (banks, traces, plots)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8080, **options: Any) -> None:
        options.setdefault("toolbox", DashboardTools())
        super().__init__(host, port, **options)
