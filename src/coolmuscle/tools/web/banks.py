"""The page's banks: list, check, upload and read back (2.2.2, 2.2.3, 6.6 ``?1000``).

An upload is the client's own (:func:`coolmuscle.client.banks.upload`, the code behind
``coolmuscle upload`` and ``Motor.upload``), run on the device by :class:`DeviceLink`
instead of a serial port.  The text is checked first by ``coolmuscle check``'s checker
(a text with errors is not sent; each error names its line); then every line goes to
``Device.execute(origin="web")`` (bank headers, bodies and ``END`` as typed), and every
bank is read back with ``?#.n`` / ``?L#.n`` and compared in canonical form
(:func:`coolmuscle.client.banks.compare_bank`).  Lines without ``.n`` address the motor
chosen on the page.  The whole upload runs in one call in the model's thread, at one
instant, so a page closed during an upload leaves the banks either as they were (the
request never arrived whole) or fully written.
"""

from __future__ import annotations

from typing import Any, TypeVar

from ...client.banks import parse_bank_listing, upload
from ...client.ops import Listen, Now, Op, Pause, Session
from ...client.program import ProgramFile, parse_program
from ...client.protocol import Exchange
from ...device import Device
from ...errors import CoolMuscleError, CoolMuscleTimeout
from ...motor.state.firmware import Firmware
from ...sim.kernel import NS_PER_S
from ..check.lint import check_program
from .hub import Note

T = TypeVar("T")


def firmware_of(device: Device) -> Firmware | None:
    """The chain's firmware profile, when the device has one (a :class:`Chain` does)."""
    firmware = getattr(device, "firmware", None)
    return firmware if isinstance(firmware, Firmware) else None


def list_banks(device: Device, motor: int) -> dict[str, Any]:
    """Every bank of ``motor`` as ``?1000.n`` lists them (6.6), and its summary line."""
    lines = device.execute(f"?1000.{motor}", origin="web", motor=motor)
    banks = parse_bank_listing(lines, motor)
    summary = [line for line in lines if line.startswith("Commands")]
    return {"banks": [{"label": label, "lines": body} for label, body in banks.items()],
            "summary": summary[0] if summary else ""}


def check_text(device: Device, text: str) -> tuple[ProgramFile, list[dict[str, Any]]]:
    """Parse and check ``text``; diagnostics as ``{line, column, severity, message}``."""
    program = parse_program(text, "<page>")
    firmware = firmware_of(device)
    report = check_program(program, firmware=firmware.name if firmware else "cm2",
                           motors=len(device.motor_ids))
    found = [{"line": d.line, "column": d.column, "severity": d.severity, "rule": d.rule,
              "message": d.message + (f" (error{d.motor_error:02d})"
                                      if d.motor_error is not None else "")}
             for d in report.diagnostics]
    return program, found


def upload_banks(device: Device, motor: int, text: str, note: Note) -> dict[str, Any]:
    """Check, send and read back ``text``; lines without ``.n`` go to ``motor``.

    ``differences`` holds what the client's upload reports: each error the motor
    printed (K23 16) and each line the read-back differs in."""
    program, diagnostics = check_text(device, text)
    if any(d["severity"] == "error" for d in diagnostics):
        return {"uploaded": False, "diagnostics": diagnostics, "differences": []}
    if not program.banks:
        return {"uploaded": False, "diagnostics": diagnostics + [{
            "line": 1, "column": 1, "severity": "error", "rule": "no-bank",
            "message": "no bank here: a bank starts with B#.n or L#.n and ends with END"}],
            "differences": []}
    link = DeviceLink(device, motor, note)
    link.send("")                          # end a bank half typed in the console
    result = link.run(upload(link.session, program, motor=motor))
    return {"uploaded": True, "diagnostics": diagnostics, "differences": result.report(),
            "banks": result.banks}


class DeviceLink:
    """Runs the client's sans-IO operations (:mod:`coolmuscle.client.ops`) on a device.

    Each line an operation sends goes to ``Device.execute(line, origin="web")`` (lines
    without ``.n`` to ``motor``) and into the pages' log (``note``); the replies the
    motor printed at once are fed to the client's protocol as received lines.  Nothing
    waits: the motor has taken a line when ``execute`` returns, so a pause passes no
    time, and an exchange the motor left unanswered is a
    :class:`~coolmuscle.errors.CoolMuscleTimeout` at once.  Runs in the model's thread.
    """

    def __init__(self, device: Device, motor: int, note: Note) -> None:
        self.device = device
        self.motor = motor
        self.note = note
        firmware = firmware_of(device)
        self.session = Session(firmware=firmware.name if firmware else None)

    def run(self, op: Op[T]) -> T:
        """Drive ``op`` to its end; its exceptions propagate."""
        result: Any = None
        error: CoolMuscleError | None = None
        while True:
            try:
                request = op.throw(error) if error is not None else op.send(result)
            except StopIteration as stop:
                value: T = stop.value
                return value
            result, error = None, None
            try:
                result = self._do(request)
            except CoolMuscleError as exc:
                error = exc

    def send(self, line: str) -> None:
        """One line to the motor, as the page's console sends it; its replies to the protocol."""
        if line:
            self.note([self.device.kernel.now, ">", line, self.motor, "web"])
        replies = self.device.execute(line, origin="web", motor=self.motor)
        self.session.protocol.receive(
            b"".join(reply.encode("latin-1", "replace") + b"\r\n" for reply in replies))

    def _do(self, request: object) -> object:
        if isinstance(request, Exchange):
            return self._exchange(request)
        if isinstance(request, Listen):
            events = self.session.protocol.events_since(request.since)
            return next((event for event in events if request.match(event)), None)
        if isinstance(request, Pause):
            return None
        if isinstance(request, Now):
            return self.device.kernel.now / NS_PER_S
        raise TypeError(f"unknown request {request!r}")

    def _exchange(self, exchange: Exchange) -> Exchange:
        protocol = self.session.protocol
        protocol.begin(exchange)
        for line in exchange.send:
            self.send(line)
        if not exchange.complete:
            protocol.abandon()
            if exchange.errors:            # the motor said why it did not answer
                raise exchange.errors[0]
            raise CoolMuscleTimeout(f"{exchange.describe()}: the motor did not answer")
        return exchange
