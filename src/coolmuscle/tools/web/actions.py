"""What a page may ask for, checked and translated to device-API calls.

Every request is one JSON object ``{"t": KIND, "id": N, ...}``; the answer is
``{"t": "result", "id": N, "ok": true, ...}`` or ``{"ok": false, "error": "..."}``.
The page writes nothing the model would not accept from a host line: CML lines run
through ``Device.execute(origin="web")`` (the motor answers them as it answers the
host line: an ``errorNN.n`` message when K23 includes 16, else silence), inputs and
the analog input through ``set_input`` / ``set_analog``, faults through
``inject_fault`` (docs/machine-file.md "Faults").  Bad requests get a clear message
(:class:`RequestError`), never a traceback.

Each request runs in the event loop's thread when its turn comes (:mod:`.turns`),
except a bank upload's pure work: its text is checked in a worker thread and its lines
are sent a slice at a time (:mod:`.banks`); :meth:`Actions.handle` hands that one back
as an awaitable.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Awaitable, Callable
from typing import Any

from ...cml.parser import parse
from ...device import Device
from ...errors import CmlSyntaxError, CoolMuscleError
from .banks import check_program_text, firmware_of, list_banks, refusal, send_slice, start_upload
from .hub import Note
from .turns import in_worker

log = logging.getLogger(__name__)

#: Longest console line accepted (the host line itself keeps 512 bytes, hostline.MAX_LINE).
MAX_LINE = 512
#: Largest bank text accepted for one upload.
MAX_BANK_TEXT = 48 * 1024

#: The machine file's faults and their parameters with the page's defaults
#: (docs/machine-file.md "Faults"; ``None``: no default, the model's own).
FAULTS: dict[str, dict[str, Any]] = {
    "overload": {"torque": 200, "clear": False},
    "over_temperature": {"temperature": 90},
    "over_current": {},
    "over_speed": {},
    "regeneration": {},
    "supply_voltage": {"volts": 12, "clear": False},
    "encoder": {},
    "stuck_input": {"input": 1, "on": True, "clear": False},
    "broken_cable": {"cable": "io", "clear": False},
}


class RequestError(CoolMuscleError, ValueError):
    """A request the page should not have sent; its text is shown to the user."""


def console_line(request: dict[str, Any]) -> str:
    """The console's ``line`` of a request: text, one line, no longer than the motor
    keeps (:data:`MAX_LINE`); else a :class:`RequestError` the page shows."""
    line = request.get("line")
    if not isinstance(line, str):
        raise RequestError("cml: 'line' must be text")
    if len(line) > MAX_LINE:
        raise RequestError(f"line too long ({len(line)} characters; the motor keeps "
                           f"{MAX_LINE})")
    if any(ch in line for ch in "\r\n"):
        raise RequestError("one line at a time (no CR/LF inside)")
    return line


class Actions:
    """Handlers of page requests; ``call`` runs a model call at the current instant."""

    def __init__(self, device: Device, call: Callable[..., Any], note: Note,
                 extra: dict[str, Callable[[dict[str, Any]], dict[str, Any]]] | None = None
                 ) -> None:
        self.device = device
        self._call = call
        self._note = note           # adds a line to every page's console log
        self._handlers: dict[str, Callable[[dict[str, Any]], dict[str, Any]]] = {
            "cml": self.cml, "input": self.input, "analog": self.analog,
            "fault": self.fault, "banks": self.banks,
            **(extra or {}),
        }

    def handle(self, request: Any) -> dict[str, Any] | Awaitable[dict[str, Any]]:
        """Answer one request (never raises): at once, or, for a request that runs in
        steps (a bank upload), an awaitable of the answer."""
        if not isinstance(request, dict):
            return {"t": "result", "ok": False, "error": "a request is a JSON object"}
        rid = request.get("id")
        rid = rid if isinstance(rid, (int, str)) and not isinstance(rid, bool) else None
        kind = request.get("t")
        if kind == "bank_upload":
            return self._answer_steps(rid, request)
        handler = self._handlers.get(kind) if isinstance(kind, str) else None
        try:
            if request.get("t") == "invalid":
                raise RequestError(str(request.get("error")))
            if handler is None:
                raise RequestError(f"unknown request {str(request.get('t'))[:40]!r}")
            return {"t": "result", "id": rid, "ok": True, **handler(request)}
        except Exception as exc:
            return _failed(rid, kind, exc)

    async def _answer_steps(self, rid: int | str | None, request: dict[str, Any]
                            ) -> dict[str, Any]:
        try:
            return {"t": "result", "id": rid, "ok": True, **await self.bank_upload(request)}
        except Exception as exc:
            return _failed(rid, "bank_upload", exc)

    # -- argument checks -----------------------------------------------------
    def _motor(self, request: dict[str, Any]) -> int:
        motor = request.get("motor", 1)
        if not _is_int(motor) or motor not in self.device.motor_ids:
            ids = self.device.motor_ids
            raise RequestError(f"no motor ID{motor} on this chain (IDs {ids[0]}..{ids[-1]})")
        return int(motor)

    # -- handlers -----------------------------------------------------------------
    def cml(self, request: dict[str, Any]) -> dict[str, Any]:
        """One console line, run as the host line would run it (origin ``web``)."""
        line = console_line(request)
        motor = self._motor(request)
        self._note([self.device.kernel.now, ">", line, motor, "web"])
        replies = self._call(lambda: self.device.execute(line, origin="web", motor=motor))
        answer: dict[str, Any] = {"replies": replies}
        if not replies:
            hint = self._silence_hint(line, motor)
            if hint:
                answer["note"] = hint
                # in the log after the line it is about, at the same instant
                self._note([self.device.kernel.now, "note", hint, motor, "web"])
        return answer

    def _silence_hint(self, line: str, motor: int) -> str | None:
        """Why a bad line got no reply: K23 lacks 16 (messages), so the motor is silent."""
        try:
            parse(line)
            return None
        except CmlSyntaxError as exc:
            if self.device.get_param(motor, 23) & 16:
                return None           # the motor printed its own errorNN line
            return (f"not CML: {exc} (the motor stays silent: K23.{motor} lacks 16, "
                    "which would print its error message)")

    def input(self, request: dict[str, Any]) -> dict[str, Any]:
        motor, number, on = self._motor(request), request.get("n"), request.get("on")
        if not _is_int(number) or not isinstance(on, bool):
            raise RequestError("input: 'n' is an input number and 'on' true or false")
        self._call(self.device.set_input, motor, number, on)
        return {"inputs": self._call(lambda: self.device.snapshot(motor).inputs)}

    def analog(self, request: dict[str, Any]) -> dict[str, Any]:
        motor, counts = self._motor(request), request.get("counts")
        if not (isinstance(counts, int) and _is_int(counts) and 0 <= counts <= 1023):
            raise RequestError("analog input is 0..1023 counts (6.6 ?74)")
        self._call(self.device.set_analog, motor, counts)
        return {}

    def fault(self, request: dict[str, Any]) -> dict[str, Any]:
        motor, name, params = self._motor(request), request.get("fault"), request.get("params", {})
        if not isinstance(name, str) or name not in FAULTS:
            raise RequestError(f"unknown fault {str(name)[:40]!r} (known: {', '.join(FAULTS)})")
        if not isinstance(params, dict) or not all(_param_ok(v) for v in params.values()):
            raise RequestError("fault parameters are numbers, true/false or short text")
        for key in params:
            if not (key.isidentifier() and key.islower()) or key in RESERVED_PARAMETERS:
                raise RequestError(f"fault {name!r} takes no parameter {key[:40]!r}")
        self._call(lambda: self.device.inject_fault(motor, name, **params))
        return {}

    def banks(self, request: dict[str, Any]) -> dict[str, Any]:
        motor = self._motor(request)
        return {"banks": self._call(list_banks, self.device, motor)}

    async def bank_upload(self, request: dict[str, Any]) -> dict[str, Any]:
        """Check the text in a worker thread, then send it a slice at a time in the
        model's thread (:mod:`.banks`)."""
        motor, text = self._motor(request), request.get("text")
        if not isinstance(text, str):
            raise RequestError("bank_upload: 'text' must be text")
        if len(text) > MAX_BANK_TEXT:
            raise RequestError(f"bank text too long ({len(text)} characters, at most "
                               f"{MAX_BANK_TEXT})")
        firmware = firmware_of(self.device)
        program, diagnostics = await in_worker(
            check_program_text, text, firmware.name if firmware else "cm2",
            len(self.device.motor_ids))
        refused = refusal(program, diagnostics)
        if refused is not None:
            return refused
        job = self._call(start_upload, self.device, motor, program, self._note)
        while (done := self._call(send_slice, job)) is None:
            await asyncio.sleep(0)         # the others' turn between two slices
        return {"diagnostics": diagnostics, **done}


#: Parameter names a fault request may not use: the names of ``inject_fault``'s own
#: arguments (a page sending them made the call fail with a traceback).
RESERVED_PARAMETERS = frozenset({"motor", "fault", "self"})


def _failed(rid: int | str | None, kind: object, exc: Exception) -> dict[str, Any]:
    """The answer to a request that failed: its message, or (a bug) an internal error
    logged with its traceback."""
    if isinstance(exc, (RequestError, CoolMuscleError, ValueError, LookupError)):
        return {"t": "result", "id": rid, "ok": False, "error": str(exc) or type(exc).__name__}
    log.error("dashboard request %r failed", str(kind)[:40], exc_info=exc)
    return {"t": "result", "id": rid, "ok": False,
            "error": "internal error (logged by the simulator)"}


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _param_ok(value: Any) -> bool:
    if isinstance(value, float):
        return math.isfinite(value)
    return isinstance(value, (bool, int)) or (isinstance(value, str) and len(value) <= 16)
