"""The page's banks: list, check, upload and read back (2.2.2, 2.2.3, 6.6 ``?1000``).

An upload is the client's own (:func:`coolmuscle.client.banks.upload`, the code behind
``coolmuscle upload`` and ``Motor.upload``), run on the device by :class:`DeviceLink`
instead of a serial port.  The text is checked first by ``coolmuscle check``'s checker
(:func:`check_program_text`: pure work, run in a worker thread, never in the event
loop; a text with errors is not sent, each error names its line); then every line goes
to ``Device.execute(origin="web")`` (bank headers, bodies and ``END`` as typed), and
every bank is read back with ``?#.n`` / ``?L#.n`` and compared in canonical form
(:func:`coolmuscle.client.banks.compare_bank`).  Lines without ``.n`` address the motor
chosen on the page.  The lines are sent in the model's thread a slice at a time
(:func:`send_slice`, ``SLICE_LINES`` lines), between which the simulator and the other
clients run on; the upload is a sender of its own (``session``), so the lines another
page or host sends meanwhile never land in its banks.  A page closed during an upload
does not cut it short: it runs to its end, so the banks are left as they were (the
request never arrived whole) or fully written.
"""

from __future__ import annotations

from collections.abc import Generator, Iterator
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
    """Parse and check ``text`` for ``device``'s firmware and chain (any thread)."""
    firmware = firmware_of(device)
    return check_program_text(text, firmware.name if firmware else "cm2",
                              len(device.motor_ids))


#: Findings of the checker an answer lists at most (then one line says how many more):
#: a 48 KiB text of errors made a half-megabyte answer.
MAX_DIAGNOSTICS = 200


def check_program_text(text: str, firmware: str, motors: int
                       ) -> tuple[ProgramFile, list[dict[str, Any]]]:
    """Parse and check ``text``; diagnostics as ``{line, column, severity, message}``
    (the first ``MAX_DIAGNOSTICS``, errors first, then a line saying how many more).
    Pure work (no model state): the web server runs it in a worker thread."""
    program = parse_program(text, "<page>")
    report = check_program(program, firmware=firmware, motors=motors)
    found = [{"line": d.line, "column": d.column, "severity": d.severity, "rule": d.rule,
              "message": d.message + (f" (error{d.motor_error:02d})"
                                      if d.motor_error is not None else "")}
             for d in report.diagnostics]
    if len(found) > MAX_DIAGNOSTICS:
        found.sort(key=lambda d: (d["severity"] != "error", d["line"]))
        more = len(found) - MAX_DIAGNOSTICS
        found = found[:MAX_DIAGNOSTICS] + [{
            "line": found[MAX_DIAGNOSTICS]["line"], "column": 1, "severity": "note",
            "rule": "more", "message": f"{more} more findings (coolmuscle check lists "
                                       "them all)"}]
    return program, found


def refusal(program: ProgramFile, diagnostics: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The answer to a text that is not sent (errors, or no bank in it); ``None``: send it."""
    if any(d["severity"] == "error" for d in diagnostics):
        return {"uploaded": False, "diagnostics": diagnostics, "differences": []}
    if not program.banks:
        return {"uploaded": False, "diagnostics": diagnostics + [{
            "line": 1, "column": 1, "severity": "error", "rule": "no-bank",
            "message": "no bank here: a bank starts with B#.n or L#.n and ends with END"}],
            "differences": []}
    return None


def upload_banks(device: Device, motor: int, text: str, note: Note) -> dict[str, Any]:
    """Check, send and read back ``text`` in one call (the model's thread; the web server
    uses the steps below instead); lines without ``.n`` go to ``motor``.

    ``differences`` holds what the client's upload reports: each error the motor
    printed (K23 16) and each line the read-back differs in."""
    program, diagnostics = check_text(device, text)
    refused = refusal(program, diagnostics)
    if refused is not None:
        return refused
    job = start_upload(device, motor, program, note)
    while (done := send_slice(job, 1 << 30)) is None:
        pass
    return {"diagnostics": diagnostics, **done}


#: Lines one slice of an upload sends in the model's thread before the others' turn.
SLICE_LINES = 32


class Upload:
    """An upload under way: its link and the client's operation driven on it."""

    def __init__(self, link: DeviceLink, steps: Iterator[None]) -> None:
        self.link = link
        self.steps = steps


def start_upload(device: Device, motor: int, program: ProgramFile, note: Note) -> Upload:
    """Begin sending ``program`` (the model's thread): a bank half typed in the page's
    console ends first, as when the page's own upload began."""
    link = DeviceLink(device, motor, note)
    link.send("", session=None)            # end a bank half typed in the console
    return Upload(link, link.drive(upload(link.session, program, motor=motor)))


def send_slice(job: Upload, lines: int = SLICE_LINES) -> dict[str, Any] | None:
    """Send about ``lines`` more lines of ``job`` (the model's thread); its result when
    it has ended (``uploaded``, ``differences``, ``banks``), else ``None``."""
    target = job.link.lines_sent + lines
    try:
        while job.link.lines_sent < target:
            next(job.steps)
    except StopIteration as stop:
        result = stop.value
        return {"uploaded": True, "differences": result.report(), "banks": result.banks}
    return None


class DeviceLink:
    """Runs the client's sans-IO operations (:mod:`coolmuscle.client.ops`) on a device.

    Each line an operation sends goes to ``Device.execute(line, origin="web")`` as a
    sender of its own (lines without ``.n`` to ``motor``) and into the pages' log
    (``note``); the replies the motor printed at once are fed to the client's protocol
    as received lines.  Nothing waits: the motor has taken a line when ``execute``
    returns, so a pause passes no time, and an exchange the motor left unanswered is a
    :class:`~coolmuscle.errors.CoolMuscleTimeout` at once.  Runs in the model's thread.
    """

    def __init__(self, device: Device, motor: int, note: Note) -> None:
        self.device = device
        self.motor = motor
        self.note = note
        self.lines_sent = 0
        firmware = firmware_of(device)
        self.session = Session(firmware=firmware.name if firmware else None)

    def run(self, op: Op[T]) -> T:
        """Drive ``op`` to its end; its exceptions propagate."""
        steps = self.drive(op)
        while True:
            try:
                next(steps)
            except StopIteration as stop:
                value: T = stop.value
                return value

    def drive(self, op: Op[T]) -> Generator[None, None, T]:
        """Drive ``op``, pausing after each exchange with the motor (``next()`` goes on;
        the operation's result is the generator's return value)."""
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
            if isinstance(request, Exchange):
                yield

    #: Feed each line's echo in front of its replies, as a host line prints them.
    echo = False

    def send(self, line: str, *, session: object = ...) -> None:
        """One line to the motor, as the page's console sends it; its replies (after
        its echo, with :attr:`echo`) to the protocol.  ``session``: the sender (default:
        this link's own)."""
        if line:
            self.note([self.device.kernel.now, ">", line, self.motor, "web"])
        replies = self.device.execute(line, origin="web", motor=self.motor,
                                      session=self if session is ... else session)
        self.lines_sent += 1
        received = [line, *replies] if self.echo else replies
        self.session.protocol.receive(
            b"".join(text.encode("latin-1", "replace") + b"\r\n" for text in received))

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
