"""The dashboard's web server: a :class:`Transport` in the simulator's own asyncio loop.

Routes (aiohttp):

* ``GET /`` the page, ``GET /static/...`` its assets (package data, uPlot bundled:
  nothing is fetched from the network at run time);
* ``GET /api/info`` what the page needs before it connects (is a token required);
* ``GET /ws`` the WebSocket: the live feed (:mod:`.hub`) out, requests (:mod:`.actions`) in;
* ``GET /api/trace.csv``, ``/api/trace.parquet``, ``/api/plot.png`` the trace recorded
  since the page's Record (the chain's
  :class:`~coolmuscle.tools.trace.recorder.TraceRecorder`, :mod:`.traces`).

The page is one more client of the device API (origin ``web``).  Access rules are in
:mod:`.access`; a WebSocket message larger than ``MAX_MESSAGE`` closes that socket
with status 1009 (message too big) and nothing else; malformed JSON is answered with
an error frame.  The pages' requests take turns with a bound per wake-up and per page
(:mod:`.turns`): a request beyond a page's queue is refused with a message, and what a
page queued is dropped when it leaves.
"""

from __future__ import annotations

import asyncio
import json
import logging
from pathlib import Path
from typing import Any

from ...device import Device
from ...errors import TransportError
from ...frontends.transports.base import Port, Transport
from ...needs import needs_extra
from ..trace.recorder import TraceRecorder
from .access import DEFAULT_HOST, DEFAULT_PORT, Access
from .actions import FAULTS, Actions
from .banks import firmware_of
from .deskpage import ChainRunner, Desk
from .downloads import Downloads
from .hub import SNAP_FIELDS, Client, Hub
from .traces import FORGET_EVERY_S, forget_old, start_recording
from .turns import Turns
from .wirefaults import WirePanel, vocabulary

with needs_extra("web", "the web page"):
    from aiohttp import WSMsgType, web

log = logging.getLogger(__name__)

#: Connections the dashboard's server keeps at once (pages, downloads, scripts): one
#: more is closed as it arrives, so a flood of connections cannot use up the process's
#: file descriptors, which the motor's other front ends share (docs/reliability.md).
MAX_CONNECTIONS = 128
#: Seconds a connection may stay without a whole request (also between requests on
#: a kept-alive one): a client trickling a request's headers is closed after it.
IDLE_TIMEOUT = 15.0


class _OneLine(logging.Filter):
    """aiohttp's request errors as one line each: a malformed request from a client
    (bad request line, header, length ...; the client gets its 400) at INFO, anything
    else at ERROR; the traceback only with ``COOLMUSCLE_DEBUG=1``."""

    def filter(self, record: logging.LogRecord) -> bool:
        import os

        from aiohttp.http_exceptions import HttpProcessingError
        if record.exc_info and not os.environ.get("COOLMUSCLE_DEBUG"):
            exc = record.exc_info[1]
            record.msg = f"web: {record.getMessage()}: {type(exc).__name__}: {exc}"
            record.args = ()
            record.exc_info = record.exc_text = None
            if isinstance(exc, HttpProcessingError):
                record.levelno, record.levelname = logging.INFO, "INFO"
        return record.levelno >= logging.getLogger("coolmuscle").getEffectiveLevel()


_HTTP_LOG = logging.getLogger("coolmuscle.web.http")
_HTTP_LOG.addFilter(_OneLine())

STATIC = Path(__file__).with_name("static")
#: Largest WebSocket message a page may send (a bank upload is at most 48 Ki characters,
#: up to three bytes each in UTF-8, plus JSON escapes).
MAX_MESSAGE = 256 * 1024
#: Seconds a closing socket waits for the page's close frame.
CLOSE_TIMEOUT = 1.0
#: Most pages connected at once.
MAX_PAGES = 100


class WebTransport(Transport):
    """Serve the dashboard on ``host:port`` (127.0.0.1:8080 by default)."""

    name = "web"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 token: str | None = None, title: str = "", record: bool = False) -> None:
        super().__init__()
        self.record = record
        self.host = host
        self.requested_port = port
        self.access = Access(host, token)
        self.title = title
        self.bound: tuple[str, int] | None = None
        self.hub: Hub | None = None
        self.actions: Actions | None = None
        self.desk: Desk | None = None
        self._runner: web.AppRunner | None = None
        #: the open pages: each socket and the request that opened it (its connection)
        self._sockets: dict[web.WebSocketResponse, web.Request] = {}
        self._recorder: TraceRecorder | None = None
        self._device: Device | None = None
        self.turns: Turns | None = None
        self.cross_site_refused = 0
        self._trimmer: asyncio.Task[None] | None = None

    # -- life cycle ---------------------------------------------------------------
    async def start(self, port: Port) -> None:
        device = port.device
        if device is None:
            raise TransportError("web: needs the chain behind the host line (Port.device)")
        self.port, self._device = port, device
        self.hub = Hub(device, port.call)
        self.actions = Actions(device, port.call, self.hub.add_log,
                               {"record": self._record_request,
                                **WirePanel(device, port.call).handlers()})
        self.desk = Desk(ChainRunner(port, device, self.hub.add_log), self.hub.add_log,
                         lambda: device.kernel.now)
        self.turns = Turns(self._handle)
        if self.record:
            self.start_recording()
        await self._listen()

    async def _listen(self) -> None:
        """Serve the page (the hub and the actions are ready)."""
        assert self.hub is not None
        self._runner = web.AppRunner(self._app(), access_log=None, handle_signals=False,
                                     shutdown_timeout=1.0, logger=_HTTP_LOG,
                                     keepalive_timeout=IDLE_TIMEOUT)
        await self._runner.setup()
        _cap_connections(self._runner.server, MAX_CONNECTIONS)
        site = web.TCPSite(self._runner, self.host, self.requested_port)
        try:
            await site.start()
        except OSError as exc:
            await self._runner.cleanup()
            raise TransportError(f"web: cannot listen on {self.host}:{self.requested_port}: "
                                 f"{exc.strerror or exc}") from exc
        addresses = self._runner.addresses
        self.bound = (addresses[0][0], addresses[0][1]) if addresses else (
            self.host, self.requested_port)
        self.hub.start()

    def start_recording(self) -> bool:
        """Start the chain's trace recorder (from now on); False when it has none.

        Recording is off until asked (the page's "Record" button, ``record=True``):
        the recorder looks at every motor after every kernel event."""
        if self._recorder is None and self.port is not None and self._device is not None:
            self._recorder = self.port.call(start_recording, self._device)
            if self._recorder is not None:
                self._trimmer = asyncio.get_running_loop().create_task(
                    self._trim_recording(), name="coolmuscle-web-recording-window")
            if self._recorder is not None and self.hub is not None:
                self.hub.add_log([self._device.kernel.now, "note",
                                  "trace recording started", 0, "web"])
                self.hub.broadcast(json.dumps({"t": "recording", "on": True}))
        return self._recorder is not None

    async def _trim_recording(self) -> None:
        """Keep the recording to its window (:func:`.traces.forget_old`), now and then."""
        while True:
            await asyncio.sleep(FORGET_EVERY_S)
            if self._recorder is not None and self.port is not None:
                try:
                    self.port.call(forget_old, self._recorder)
                except Exception:              # a model failure must not end the server
                    log.exception("dashboard: trimming the recording failed")

    def _record_request(self, _request: dict[str, Any]) -> dict[str, Any]:
        if not self.start_recording():
            raise ValueError("no trace recorder here: only a simulated chain is recorded")
        return {"recording": True}

    def describe(self) -> str:
        text = f"web: {self.url}"
        if self.access.token is not None:
            text += f" (token: {self.access.token})"
        return text

    @property
    def url(self) -> str:
        host, port = self.bound or (self.host, self.requested_port)
        shown = f"[{host}]" if ":" in host else host
        return f"http://{shown}:{port}/"

    def info(self) -> dict[str, Any]:
        host, port = self.bound or (self.host, self.requested_port)
        return {"host": host, "port": port, "url": self.url, "token": self.access.token}

    async def close(self) -> None:
        await asyncio.gather(*(_close_page(ws, request)
                               for ws, request in list(self._sockets.items())),
                             return_exceptions=True)
        if self._trimmer is not None:
            self._trimmer.cancel()
            await asyncio.gather(self._trimmer, return_exceptions=True)
            self._trimmer = None
        if self.turns is not None:
            await self.turns.close_all()
        if self.hub is not None:
            await self.hub.close()
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None

    # -- the application -------------------------------------------------------
    def _app(self) -> web.Application:
        app = web.Application(middlewares=[self._guard], client_max_size=MAX_MESSAGE)
        app.router.add_get("/", self._index)
        app.router.add_get("/api/info", self._info)
        app.router.add_get("/ws", self._websocket)
        if self.port is not None:              # a served chain: its trace
            downloads = Downloads(self.port, lambda: self._recorder, self.title)
            app.router.add_get("/api/trace.{fmt:csv|parquet}", downloads.trace)
            app.router.add_get("/api/plot.png", downloads.plot)
        self._add_routes(app)
        app.router.add_static("/static", STATIC, follow_symlinks=False)
        return app

    def _add_routes(self, app: web.Application) -> None:
        """More routes of a page of another kind (:mod:`.linepage`)."""

    @web.middleware
    async def _guard(self, request: web.Request, handler: Any) -> web.StreamResponse:
        """Host check everywhere; the token everywhere but the page and its assets."""
        if not self.access.host_ok(request.headers.get("Host")):
            return _error(421, "this dashboard answers on its loopback address only")
        public = request.path == "/" or request.path.startswith("/static/") \
            or request.path == "/api/info"
        if not public and not self.access.token_ok(_token(request)):
            return _error(401, "the dashboard needs the token printed when the simulator "
                               "started")
        if request.path.startswith("/api/") and not public and not self.access.fetch_ok(
                request.headers.get("Origin"), request.headers.get("Sec-Fetch-Site"),
                request.headers.get("Host")):
            self.cross_site_refused += 1
            return _error(403, "a download asked by another site's page is refused")
        try:
            response: web.StreamResponse = await handler(request)
        except web.HTTPException as exc:
            return _error(exc.status, exc.reason or "error")
        except Exception:
            log.exception("dashboard request %s failed", request.path)
            return _error(500, "internal error (logged by the simulator)")
        response.headers.setdefault("X-Content-Type-Options", "nosniff")
        return response

    async def _index(self, _request: web.Request) -> web.StreamResponse:
        response = web.FileResponse(STATIC / "index.html")
        response.headers["Cache-Control"] = "no-cache"
        response.headers["Content-Security-Policy"] = (
            "default-src 'self'; connect-src 'self'; img-src 'self' data: blob:; "
            "style-src 'self'; script-src 'self'; frame-ancestors 'none'")
        return response

    async def _info(self, _request: web.Request) -> web.StreamResponse:
        return web.json_response({"token_required": self.access.token_required,
                                  "title": self.title, "pages": len(self._sockets),
                                  "max_pages": MAX_PAGES})

    def _hello(self) -> dict[str, Any]:
        assert self.port is not None and self.hub is not None and self._device is not None
        device = self._device
        firmware = firmware_of(device)
        counts = self.port.call(_io_counts, device)
        return {"t": "hello", "motors": list(device.motor_ids),
                "firmware": firmware.name if firmware else "",
                "title": self.title, "time": device.kernel.now, "fields": SNAP_FIELDS,
                "io": counts, "faults": FAULTS, "wire": vocabulary(),
                "log": list(self.hub.history),
                "snap": json.loads(self.hub.snapshot_frame()),
                "recording": self._recorder is not None, "line": self.line_info()}

    def line_info(self) -> dict[str, Any]:
        """What the page says of the line: virtual or a real motor (its badge)."""
        return {"kind": "virtual", "text": "virtual"}

    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        if not self.access.origin_ok(request.headers.get("Origin"), request.headers.get("Host")):
            return _error(403, "WebSocket from another site refused")
        if len(self._sockets) >= MAX_PAGES:
            return _error(503, f"too many pages open ({MAX_PAGES}); close one")
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE, heartbeat=20.0,
                                   compress=False, timeout=CLOSE_TIMEOUT)
        await ws.prepare(request)
        assert self.hub is not None
        self._sockets[ws] = request
        client = Client(ws.send_str)
        try:
            hello, seen = self._hello(), self.hub.pending()     # one instant: no await
            await ws.send_str(json.dumps(hello, separators=(",", ":")))
            self.hub.add(client, seen)
            await self._receive(ws, client, request)
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            self.hub.remove(client)
            self._sockets.pop(ws, None)
        return ws

    async def _receive(self, ws: web.WebSocketResponse, client: Client,
                       request: web.Request) -> None:
        """Queue the page's requests for their turn (:mod:`.turns`); one beyond its
        queue's bound is refused with a message; what it queued is dropped when it leaves.
        Reading pauses for the others once the pages have read their share of a wake-up."""
        assert self.turns is not None
        page = self.turns.open(lambda answer: self._answer(client, answer),
                               lambda: ws.closed or request.transport is None)
        try:
            async for msg in ws:
                if page.gone():
                    break                       # the connection was lost: read no further
                if msg.type == WSMsgType.TEXT:
                    asked = _loads(msg.data)
                    if not self.turns.submit(page, asked):
                        self._answer(client, _busy(asked, self.turns.max_queued))
                elif msg.type == WSMsgType.BINARY:
                    client.queue_direct(json.dumps({"t": "result", "ok": False,
                                                    "error": "send JSON text frames"}))
                elif msg.type == WSMsgType.ERROR:
                    log.info("dashboard WebSocket closed: %s", ws.exception())
                    break
                await self.turns.read_turn()    # the other clients' turn, now and then
        finally:
            self.turns.close(page)

    def _handle(self, request: Any) -> Any:
        """Run one request of a page: the desk's (:mod:`.deskpage`) as steps the page
        waits for (an awaitable, run as a task by :mod:`.turns`), the others at once."""
        assert self.actions is not None
        if self.desk is not None and isinstance(request, dict) \
                and self.desk.handles(request.get("t")):
            return self.desk.handle(request)
        return self.actions.handle(request)

    def _answer(self, client: Client, answer: dict[str, Any]) -> None:
        assert self.hub is not None
        client.queue_direct(json.dumps(answer, separators=(",", ":")))
        self.hub.changed()


async def _close_page(ws: web.WebSocketResponse, request: web.Request) -> None:
    """Close a page's socket (1001, going away) within ``CLOSE_TIMEOUT`` in all.

    The close frame is written with a drain, and a page that does not read (a frozen
    tab, a peer gone without a FIN) never lets the drain end: ``ws.close`` bounds only
    its wait for the page's answer.  Past the bound the connection is aborted, so a
    stop never waits for a page."""
    try:
        async with asyncio.timeout(CLOSE_TIMEOUT):
            await ws.close(code=1001, message=b"simulator stopping")
    except TimeoutError:
        if request.transport is not None:
            request.transport.abort()


def _busy(request: Any, bound: int) -> dict[str, Any]:
    """The answer to a request beyond its page's queue (not run)."""
    rid = request.get("id") if isinstance(request, dict) else None
    rid = rid if isinstance(rid, (int, str)) and not isinstance(rid, bool) else None
    return {"t": "result", "id": rid, "ok": False,
            "error": f"busy: {bound} requests of this page are waiting to run; this one "
                     "was not run (wait for their answers)"}


def _io_counts(device: Device) -> dict[str, int]:
    firmware = firmware_of(device)
    return {"inputs": firmware.inputs if firmware else 6,
            "outputs": firmware.outputs if firmware else 4}


def _token(request: web.Request) -> str | None:
    header = request.headers.get("Authorization", "")
    if header.startswith("Bearer "):
        return header[7:].strip()
    return request.query.get("token")


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number here")


def _loads(text: str) -> Any:
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except (ValueError, RecursionError) as exc:
        return {"t": "invalid", "error": f"not a JSON request: {exc}"[:200]}


def _error(status: int, message: str) -> web.Response:
    return web.json_response({"error": message}, status=status)


def _cap_connections(server: Any, limit: int) -> None:
    """Close a connection beyond ``limit`` as soon as it is made: aiohttp's server
    tells itself of every new connection through ``connection_made``; the handler is
    closed once it has started (its own ``force_close``), so aiohttp ends it as any
    connection it drops.  Logged once a burst (at INFO)."""
    made = server.connection_made
    over = [False]

    def connection_made(handler: Any, transport: Any) -> None:
        made(handler, transport)
        if len(server.connections) <= limit:
            over[0] = False
            return
        if not over[0]:
            over[0] = True
            log.info("web: more than %d connections: the newest are closed", limit)
        asyncio.get_running_loop().call_soon(handler.force_close)
    server.connection_made = connection_made
