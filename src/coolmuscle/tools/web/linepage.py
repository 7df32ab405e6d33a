"""The page in front of a real motor: ``coolmuscle web PORT_OR_URL`` (docs/real-motor.md).

The same page, JavaScript and requests as the virtual dashboard (:mod:`.server`), served
for a :class:`~.line.LineDevice` instead of a chain: the cards and charts show what the
poll reads, the log the lines the page sent, their replies and the motors' reports, and
every request asks the motor over the line (user's requests before the poll):

* ``cml``: the console line with the host library's ``send_line`` (fenced, so its
  replies and errors are complete when it returns);
* ``banks`` / ``bank_upload``: ``?1000.n``; the checker of ``coolmuscle check``, then the
  client's upload with read-back (:func:`coolmuscle.client.banks.upload`), as ``coolmuscle
  upload`` does;
* the desk's (:mod:`.deskpage`): the K editor, the buttons, scan, backup, restore;
* inputs, the analog input, faults, wire faults and the trace recorder belong to a
  virtual motor: refused with a line that says so.

With a twin (:mod:`.twin`) the snapshot rows carry the virtual motor's position, speed
and torque beside the real ones, and the page hears each difference beyond the
``compare`` tolerances.
"""

from __future__ import annotations

import json
import logging
from typing import Any

from aiohttp import web

from ...client.banks import all_banks, upload
from ...client.program import parse_program
from ...errors import CoolMuscleError, TransportError
from ...frontends.transports.base import Port
from ...motor.state.firmware import get_firmware
from ..check.lint import check_program
from .access import DEFAULT_HOST, DEFAULT_PORT
from .actions import MAX_BANK_TEXT, console_line
from .deskpage import Desk
from .hub import SNAP_FIELDS, Hub
from .line import LineDevice
from .server import WebTransport
from .turns import Turns
from .twin import TWIN_FIELDS, LiveTwin

__all__ = ["LinePage"]

log = logging.getLogger(__name__)

_VIRTUAL_ONLY = {
    "input": "the inputs of a real motor are wired, not clicked: the page shows them "
             "(K23 2 reports, ?70)",
    "analog": "the analog input of a real motor is wired (?74 reads it)",
    "fault": "faults are injected into a virtual motor only",
    "wire_fault": "wire faults are injected into a virtual motor's doors only",
    "wire_clear": "wire faults are injected into a virtual motor's doors only",
    "wire_faults": "wire faults are injected into a virtual motor's doors only",
    "record": "the trace recorder records a virtual chain; with --twin, Save capture "
              "keeps the session",
}


class LineHub(Hub):
    """The feed of a real line: rows of what the poll read (``None`` where nothing was),
    with the twin's position, speed and torque when there is one."""

    def __init__(self, line: LineDevice, twin: LiveTwin | None) -> None:
        super().__init__(line, lambda fn, *args: fn(*args))
        self.line = line
        self.twin = twin

    def rows(self) -> list[list[Any]]:
        out = []
        for motor in self.line.motor_ids:
            v = self.line.values(motor)
            free = v.status is not None and bool(v.status & 16)
            row: list[Any] = [motor, v.position, None, v.speed, v.torque, v.status,
                              v.inputs, v.outputs, v.temperature, None, None, None, None,
                              not free if v.status is not None else None]
            if self.twin is not None:
                row += self.twin.values(motor)
            out.append(row)
        return out


class LinePage(WebTransport):
    """The dashboard of a real motor on ``host:port`` (127.0.0.1:8080 by default)."""

    name = "web"

    def __init__(self, line: LineDevice, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 *, twin: LiveTwin | None = None, token: str | None = None,
                 title: str = "") -> None:
        super().__init__(host, port, token=token, title=title)
        self.line = line
        self.twin = twin

    async def start(self, port: Port) -> None:
        raise TransportError("the page of a real motor serves a line (open()), not a chain")

    async def open(self) -> None:
        """Serve the page and start the poll."""
        line = self.line
        self.hub = LineHub(line, self.twin)
        line.log = self.hub.add_log
        self.desk = Desk(line, self.hub.add_log, lambda: line.kernel.now)
        self.turns = Turns(self._handle)
        if self.twin is not None:
            self.twin.attach(line, self.hub)
        await self._listen()
        line.start()

    async def close(self) -> None:
        await super().close()
        if self.twin is not None:
            await self.twin.close()
        await self.line.close()

    # -- what the page hears first --------------------------------------------------
    def line_info(self) -> dict[str, Any]:
        line = self.line
        info: dict[str, Any] = {"kind": "real", "text": line.describe(), "port": line.url,
                                "baud": line.baud, "rate": line.line_baud,
                                "poll": line.plan.describe(), "silent": line.silent}
        if self.twin is not None:
            info["twin"] = self.twin.info()
        return info

    def _hello(self) -> dict[str, Any]:
        assert self.hub is not None
        line = self.line
        firmware = get_firmware(line.firmware_of(line.motor_ids[0]))
        fields = list(SNAP_FIELDS) + (list(TWIN_FIELDS) if self.twin is not None else [])
        return {"t": "hello", "motors": list(line.motor_ids), "firmware": firmware.name,
                "title": self.title, "time": line.kernel.now, "fields": fields,
                "io": {"inputs": firmware.inputs, "outputs": firmware.outputs},
                "faults": {}, "wire": None, "log": list(self.hub.history),
                "snap": json.loads(self.hub.snapshot_frame()), "recording": False,
                "line": self.line_info()}

    def greet_again(self) -> None:
        """The motors changed (a scan): every page starts over with a new hello."""
        if self.hub is not None:
            self.hub.broadcast(json.dumps(self._hello(), separators=(",", ":")))

    # -- requests ---------------------------------------------------------------------
    async def _handle(self, request: Any) -> dict[str, Any]:
        if not isinstance(request, dict):
            return {"t": "result", "ok": False, "error": "a request is a JSON object"}
        rid = request.get("id")
        rid = rid if isinstance(rid, (int, str)) and not isinstance(rid, bool) else None
        kind = request.get("t")
        assert self.desk is not None
        if self.desk.handles(kind):
            answer = await self.desk.handle(request)
            if kind == "scan" and answer.get("ok"):
                self.greet_again()
            return answer
        try:
            if kind == "invalid":
                raise ValueError(str(request.get("error")))
            if kind in _VIRTUAL_ONLY:
                raise ValueError(_VIRTUAL_ONLY[str(kind)])
            handler = {"cml": self._cml, "banks": self._banks,
                       "bank_upload": self._bank_upload}.get(str(kind))
            if handler is None:
                raise ValueError(f"unknown request {str(kind)[:40]!r}")
            return {"t": "result", "id": rid, "ok": True, **(await handler(request))}
        except (CoolMuscleError, ValueError, LookupError) as exc:
            return {"t": "result", "id": rid, "ok": False, "error": str(exc) or type(exc).__name__}
        except Exception:
            log.exception("line page request %r failed", kind)
            return {"t": "result", "id": rid, "ok": False,
                    "error": "internal error (logged by coolmuscle)"}

    def _motor(self, request: dict[str, Any]) -> int:
        motor = request.get("motor", 1)
        ids = self.line.motor_ids
        if not (isinstance(motor, int) and not isinstance(motor, bool)) or motor not in ids:
            raise ValueError(f"no motor ID{motor} on {self.line.url} (IDs {ids[0]}..{ids[-1]})")
        return motor

    async def _cml(self, request: dict[str, Any]) -> dict[str, Any]:
        replies = await self.line.console(console_line(request), self._motor(request))
        return {"replies": replies}

    async def _banks(self, request: dict[str, Any]) -> dict[str, Any]:
        motor = self._motor(request)
        banks = await self.line.run(all_banks(self.line.session, motor))
        return {"banks": {"banks": [{"label": label, "lines": body}
                                    for label, body in banks.items()],
                          "summary": f"{len(banks)} bank{'s' if len(banks) != 1 else ''} "
                                     f"on ID{motor} (?1000.{motor})"}}

    async def _bank_upload(self, request: dict[str, Any]) -> dict[str, Any]:
        motor, text = self._motor(request), request.get("text")
        if not isinstance(text, str):
            raise ValueError("bank_upload: 'text' must be text")
        if len(text) > MAX_BANK_TEXT:
            raise ValueError(f"bank text too long ({len(text)} characters, at most "
                             f"{MAX_BANK_TEXT})")
        program = parse_program(text, "<page>")
        report = check_program(program, firmware=self.line.firmware_of(motor),
                               motors=len(self.line.motor_ids))
        diagnostics = [{"line": d.line, "column": d.column, "severity": d.severity,
                        "rule": d.rule, "message": d.message + (
                            f" (error{d.motor_error:02d})" if d.motor_error is not None
                            else "")} for d in report.diagnostics]
        if any(d["severity"] == "error" for d in diagnostics):
            return {"uploaded": False, "diagnostics": diagnostics, "differences": []}
        if not program.banks:
            return {"uploaded": False, "diagnostics": diagnostics + [{
                "line": 1, "column": 1, "severity": "error", "rule": "no-bank",
                "message": "no bank here: a bank starts with B#.n or L#.n and ends with "
                           "END"}], "differences": []}
        self.line.log([self.line.kernel.now, ">", f"(bank upload: {len(text.splitlines())} "
                       "lines)", motor, "web"])
        result = await self.line.run(upload(self.line.session, program, motor=motor))
        return {"uploaded": True, "diagnostics": diagnostics, "differences": result.report(),
                "banks": result.banks}

    # -- the twin's capture ----------------------------------------------------------
    def _add_routes(self, app: web.Application) -> None:
        app.router.add_get("/api/capture.cml", self._capture)

    async def _capture(self, _request: web.Request) -> web.StreamResponse:
        if self.twin is None:
            return web.json_response({"error": "no twin: start coolmuscle web with --twin"},
                                     status=409)
        async with self.line.quiet():            # no query left without its answer
            body = self.twin.capture_text().encode("utf-8")
        return web.Response(body=body, content_type="text/plain", charset="utf-8", headers={
            "Content-Disposition": 'attachment; filename="coolmuscle-capture.cml"'})
