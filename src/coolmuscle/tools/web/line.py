"""The line-backed device: what the page needs of a chain, asked over a serial line.

``coolmuscle web PORT`` shows a real motor (docs/real-motor.md "The page on a real
motor"): the page's JavaScript and its requests are those of the virtual page, and
this class answers them by asking the motor over any pyserial URL with the host
library's asyncio driver (:class:`coolmuscle.client.aio_driver.AsyncDriver`).  It holds
no motor behaviour: every value it shows is a reply the motor gave.

* **The line.** Opened and scanned as ``coolmuscle scan`` does
  (:func:`coolmuscle.tools.desk.linescan.scan_port`: the IDs, the K20 rate, the
  firmware of each title); :meth:`LineDevice.scan` opens it again and scans anew.
* **The poll.** Position ``?96``, speed ``?97``, torque ``?98`` every round; status
  ``?99`` every round while the motor does not report by itself (K23 without 1, ch. 3),
  else after each of the user's requests and every :data:`STATUS_GUARD` seconds at rest;
  temperature ``?71`` every :data:`TEMPERATURE_EVERY` rounds (6.6).  A round's bytes are
  counted for the longest replies (:func:`round_bytes`) and the rounds are spaced so the
  poll takes at most :data:`POLL_SHARE` of the line at its K20 rate
  (:func:`poll_period`); the rest is the user's.
* **The user first.** A request of the page (:meth:`LineDevice.run`, a console line)
  waits at most for the one poll query on the line; the poll waits while any request
  of the user waits or runs.
* **Events.** Lines nobody asked for (``Ux.n=`` reports, K23 1; ``IN``/``OUT`` reports,
  2 and 4; messages) go to the page's log as they come, and a status report updates
  the status at once.
* **The clock** of the page is the wall clock from the moment the line was opened
  (``kernel.now`` in nanoseconds, as the virtual page's virtual time).
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

from ...client.aio_driver import AsyncDriver
from ...client.banks import send_line
from ...client.ops import Op, Session, query
from ...client.protocol import MotorEvent
from ...client.replies import parse_int_reply
from ...cml.ast import inner_motor
from ...cml.parser import parse
from ...device import Event, MotorSnapshot
from ...device.hostline import BAUD_RATES
from ...errors import CmlSyntaxError, CoolMuscleError, CoolMuscleTimeout, MotorError
from ...motor.status import ALARM_BITS, Report, Ux
from ..desk.errors import DeskError
from ..desk.linescan import REPLY_TIMEOUT, SCAN_ORDER, FoundMotor, ScanResult, scan_port
from ..desk.ports import open_port, port_url
from ..desk.restorer import LineControl

__all__ = ["LineDevice", "PollPlan", "POLL_SHARE", "round_bytes", "poll_period",
           "open_line", "addressed"]

log = logging.getLogger(__name__)

T = TypeVar("T")
R = TypeVar("R")

#: At most this share of the line's time (either direction) goes to the poll.
POLL_SHARE = 0.25
#: The poll never runs faster than this (Hz): the page draws 30 frames a second, a
#: motor's values change little within 50 ms.
MAX_POLL_HZ = 20.0
#: Seconds a poll query may take before the motor counts as silent.
POLL_TIMEOUT = 0.5
#: While the motor is silent, one try every this many seconds.
SILENT_RETRY = 1.0
#: Temperature (``?71``) every this many rounds.
TEMPERATURE_EVERY = 10
#: With reports on (K23 1), ``?99`` at rest every this many seconds (a lost report).
STATUS_GUARD = 2.0
#: Seconds a console line's answer may take (a listing of 200 items at 9.6 kbps).
CONSOLE_TIMEOUT = 5.0
#: Bits of one byte on the line: start, 8 data, stop (5.6.1; no parity, K82=0).
BITS_PER_BYTE = 10

#: The poll's queries (6.6): number, reply name, field, the longest reply's value.
QUERIES: tuple[tuple[int, str, str, str], ...] = (
    (96, "Px", "position", "-2147483648"),
    (97, "Sx", "speed", "-2147483648"),
    (98, "Ix", "torque", "-1000"),
    (99, "Ux", "status", "1023"),
    (71, "Temp", "temperature", "-100"),
)


def round_bytes(motors: Sequence[int], echo: bool = True) -> tuple[int, int]:
    """The most bytes one poll round of ``motors`` sends and receives: each query and
    CR; its echo (ch. 3 K23 8 off) and the longest reply, each with CR LF (K70=1)."""
    sent = received = 0
    for motor in motors:
        for number, name, _field, longest in QUERIES:
            asked = f"?{number}.{motor}"
            sent += len(asked) + 1
            received += (len(asked) + 2 if echo else 0) + len(f"{name}.{motor}={longest}") + 2
    return sent, received


def poll_period(baud: int, motors: Sequence[int], share: float = POLL_SHARE) -> float:
    """Seconds from the start of one round to the next: the round's bytes take at most
    ``share`` of the line at ``baud`` (each direction), and at most :data:`MAX_POLL_HZ`."""
    sent, received = round_bytes(motors)
    busy = max(sent, received) * BITS_PER_BYTE / baud
    return max(busy / share, 1.0 / MAX_POLL_HZ)


@dataclass
class PollPlan:
    """How the line is polled: its rate, the period, what a round costs."""

    baud: int
    motors: tuple[int, ...]
    period: float = field(init=False)

    def __post_init__(self) -> None:
        self.period = poll_period(self.baud, self.motors)

    def describe(self) -> str:
        sent, received = round_bytes(self.motors)
        busy = max(sent, received) * BITS_PER_BYTE / self.baud
        return (f"{1 / self.period:.1f} rounds a second ({received} bytes from the motors "
                f"a round at most: {busy * 1000:.0f} ms of {self.baud} bit/s, "
                f"{busy / self.period:.0%} of the line)")


class StampedPort:
    """A pyserial port whose reads are stamped where they happen, in the driver's
    reader thread: the page's loop hands the bytes on later (by as long as it was busy),
    and the twin compares instants to the millisecond (:meth:`LineDevice.received_at`).
    Everything else is the port's own."""

    def __init__(self, port: Any) -> None:
        object.__setattr__(self, "_port", port)
        object.__setattr__(self, "_reads", collections.deque(maxlen=4096))

    @classmethod
    def wrap(cls, port: Any) -> Any:
        """``port`` stamped; its class keeps the port's module, by which the asyncio
        driver tells a ``socket://`` port (whose ``in_waiting`` says only 0 or 1)."""
        kind = type(cls.__name__, (cls,), {"__module__": type(port).__module__})
        return kind(port)

    def read(self, size: int = 1) -> bytes:
        data: bytes = self._port.read(size)
        if data:
            self._reads.append((time.monotonic(), len(data)))
        return data

    def taken(self, size: int) -> float | None:
        """When the last of the next ``size`` bytes handed on was read."""
        at = None
        while size > 0 and self._reads:
            at, got = self._reads.popleft()
            size -= got
        return at

    def __getattr__(self, name: str) -> Any:
        return getattr(self._port, name)

    def __setattr__(self, name: str, value: Any) -> None:
        setattr(self._port, name, value)


class WallClock:
    """The page's clock on a real motor: nanoseconds since the line was opened."""

    def __init__(self) -> None:
        self._start = time.monotonic_ns()

    @property
    def now(self) -> int:
        return time.monotonic_ns() - self._start


@dataclass
class Values:
    """The latest values polled from one motor (``None``: not read yet)."""

    position: int | None = None
    speed: int | None = None
    torque: int | None = None
    status: int | None = None
    temperature: int | None = None
    inputs: int | None = None
    outputs: int | None = None
    k23: int | None = None
    status_at: float = 0.0
    status_due: bool = True


def addressed(line: str, default: int) -> int:
    """The motor whose fence ends a console line (``?96.n`` after it, the host library's
    ``send_line``): the farthest one the line names (its replies come after those of the
    motors before it on the chain), else ``default``, the motor chosen on the page."""
    try:
        statements = [s for parsed in parse(line) for s in parsed.statements]
    except CmlSyntaxError:
        return default
    named = [m for m in (inner_motor(s) for s in statements) if m is not None]
    return max(named, default=default)


def open_line(port: str, bauds: Sequence[int] | None = None,
              ids: Sequence[int] | None = None, timeout: float = REPLY_TIMEOUT
              ) -> tuple[Any, ScanResult]:
    """Open PORT and scan it (blocking): the port, left at the rate found, and what the
    scan found.  :class:`~coolmuscle.tools.desk.errors.DeskError` when nothing answers."""
    url = port_url(port)
    rates = tuple(bauds) if bauds else SCAN_ORDER
    opened = open_port(url, rates[0])
    try:
        result = scan_port(opened, url, bauds=rates, ids=ids, timeout=timeout)
    except BaseException:
        opened.close()
        raise
    opened.reset_input_buffer()
    return opened, result


class LineDevice:
    """A chain behind a serial line, as the page sees it (module docstring)."""

    def __init__(self, port: Any, found: ScanResult, *, poll: bool = True) -> None:
        self.url = found.url
        self.kernel = WallClock()
        self.polling = poll
        self._port = StampedPort.wrap(port)
        self._found = found
        self._listeners: list[Callable[[Event], None]] = []
        self._values: dict[int, Values] = {}
        self._user = 0                         # the user's requests waiting or running
        self._no_user = asyncio.Event()
        self._no_user.set()
        self._held: str | None = None          # an operation that holds the line
        self._poller: asyncio.Task[None] | None = None
        self._rounds = 0
        self.silent: str | None = None        # why the motors do not answer
        #: called after each poll round (the twin samples then)
        self.on_round: list[Callable[[], None]] = []
        #: ``tap(direction, data)``: every byte written (``">"``) and read (``"<"``)
        self.taps: list[Callable[[str, bytes], None]] = []
        #: when (``time.monotonic()``, in the reader thread) the bytes of the latest
        #: ``"<"`` tap call were read from the port (``None``: not known)
        self.read_at: float | None = None
        #: adds ``[time_ns, ">", line, motor, "web"]`` to the page's log (the hub's)
        self.log: Callable[[list[Any]], None] = lambda entry: None
        self.session, self.driver = self._new_driver()
        self.plan = PollPlan(self.line_baud, self.motor_ids)

    # -- what the page reads ------------------------------------------------------
    @property
    def motor_ids(self) -> tuple[int, ...]:
        return self._found.ids

    @property
    def rounds(self) -> int:
        """Poll rounds done so far."""
        return self._rounds

    @property
    def found(self) -> ScanResult:
        return self._found

    @property
    def where(self) -> str:
        return self.url

    @property
    def baud(self) -> int | None:
        """The wire's rate (``None``: a socket, no wire)."""
        return self._found.baud

    @property
    def line_baud(self) -> int:
        """The rate the poll is paced for: the wire's, else ID1's K20 (a socket to a
        serial server or a simulator stands for a line at that rate)."""
        if self._found.baud:
            return self._found.baud
        first = self._found.motors[0].k20 if self._found.motors else None
        return BAUD_RATES.get(first if first is not None else 0, 38400)

    def firmware_of(self, motor: int) -> str:
        found = self._motor(motor)
        return found.firmware if found is not None and found.firmware != "?" else "cm2"

    def _motor(self, motor: int) -> FoundMotor | None:
        return next((m for m in self._found.motors if m.motor == motor), None)

    def describe(self) -> str:
        """``real motor on /dev/ttyUSB0 at 38.4 kbps`` (the page's badge)."""
        count = len(self.motor_ids)
        what = "real motor" if count == 1 else f"{count} real motors"
        if self._found.baud:
            return f"{what} on {self.url} at {self._found.baud / 1000:g} kbps"
        return f"{what} on {self.url} (K20 {self.line_baud / 1000:g} kbps)"

    def values(self, motor: int) -> Values:
        return self._values.setdefault(motor, Values())

    def snapshot(self, motor: int) -> MotorSnapshot:
        """The latest polled values (0 where nothing was read; the page uses
        :meth:`values`, which tells)."""
        v = self.values(motor)
        return MotorSnapshot(motor, self.kernel.now, v.position or 0, v.position or 0, 0,
                             v.speed or 0, 0.0, v.torque or 0, v.status or 0, v.inputs or 0,
                             v.outputs or 0, v.temperature or 0, 0, 0, 0,
                             enabled=not (v.status or 0) & Ux.MOTOR_FREE)

    def subscribe(self, listener: Callable[[Event], None]) -> Callable[[], None]:
        """The page's log: the user's lines, their replies, and the motors' events."""
        self._listeners.append(listener)

        def remove() -> None:
            if listener in self._listeners:
                self._listeners.remove(listener)
        return remove

    def _emit(self, kind: Any, text: str, motor: int, value: int | None = None,
              origin: Any = "motor") -> None:
        event = Event(self.kernel.now, motor, kind, text, value, origin)
        for listener in list(self._listeners):
            try:
                listener(event)
            except Exception:
                log.exception("line event listener failed")

    # -- life cycle --------------------------------------------------------------
    def _new_driver(self) -> tuple[Session, AsyncDriver]:
        session = Session(timeout=CONSOLE_TIMEOUT)
        driver = AsyncDriver(self._port, session)
        driver.listeners.append((self._on_event, lambda _event: True))
        driver.taps.append(self._tap)
        driver.on_failure.append(self._on_failure)
        driver.start()
        return session, driver

    def _tap(self, direction: str, data: bytes) -> None:
        if direction == "<":
            taken: float | None = self._port.taken(len(data))
            self.read_at = taken
        for tap in list(self.taps):
            try:
                tap(direction, data)
            except Exception:
                log.exception("line tap failed")

    def start(self) -> None:
        """Start the poll (the driver reads already)."""
        if self.polling and self._poller is None:
            self._poller = asyncio.get_running_loop().create_task(self._poll(),
                                                                  name="coolmuscle-line-poll")

    async def _stop_poll(self) -> None:
        if self._poller is not None:
            self._poller.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._poller
            self._poller = None

    async def close(self) -> None:
        await self._stop_poll()
        self.driver.close()
        with contextlib.suppress(Exception):
            self._port.close()

    def _on_failure(self, exc: BaseException) -> None:
        self.silent = f"the line failed: {exc} (Scan opens it again)"
        self._emit("message", self.silent, 0, origin="web")

    # -- the user's requests -----------------------------------------------------
    @contextlib.asynccontextmanager
    async def _users_turn(self) -> AsyncIterator[None]:
        self._user += 1
        self._no_user.clear()
        try:
            yield
        finally:
            self._user -= 1
            if self._user == 0:
                self._no_user.set()

    @contextlib.asynccontextmanager
    async def quiet(self, settle: float = 0.05) -> AsyncIterator[None]:
        """The line with nothing in flight: every exchange answered, the poll paused,
        ``settle`` seconds for what the motors send last (the end of a capture)."""
        async with self._users_turn(), self.driver.lock:
            await asyncio.sleep(settle)
            yield

    def _check_free(self) -> None:
        if self._held is not None:
            raise DeskError(f"the line is busy with a {self._held}: try again when it "
                            "has ended")

    async def run(self, op: Op[T]) -> T:
        """Run one client operation for the user, before the poll."""
        self._check_free()
        async with self._users_turn():
            try:
                return await self.driver.run(op)
            finally:
                self._status_due()

    def _status_due(self) -> None:
        for values in self._values.values():
            values.status_due = True

    async def console(self, line: str, motor: int) -> list[str]:
        """A line typed in the page's console, its replies (6.6) or the motor's error."""
        self.log([self.kernel.now, ">", line, motor, "web"])
        motor = addressed(line, motor)
        try:
            replies = await self.run(send_line(self.session, motor, line, CONSOLE_TIMEOUT))
        except MotorError as exc:            # as the motor printed it (K23 16)
            text = exc.motor_line(motor)
            self._emit("message", text, motor, origin="web")
            return [text]
        for reply in replies:
            self._emit("reply", reply, motor, origin="web")
        if "K23" in line.upper():
            self.values(motor).k23 = None          # read again by the next round
        return replies

    async def drive(self, work: Callable[[Callable[[Op[Any]], Any], LineControl], R]) -> R:
        """``work`` (a restore) drives operations from a worker thread, the line held:
        the poll waits and the page's other requests are refused meanwhile."""
        self._check_free()
        loop = asyncio.get_running_loop()

        def run(op: Op[Any]) -> Any:
            future: concurrent.futures.Future[Any] = asyncio.run_coroutine_threadsafe(
                self.driver.run(op), loop)
            return future.result()
        async with self._users_turn():
            self._held = "restore"
            try:
                return await asyncio.to_thread(work, run, LineControl(self._set_rate,
                                                                      self._set_parity))
            finally:
                self._held = None
                self._status_due()

    def _set_rate(self, baud: int) -> None:
        if self._found.baud is not None:
            self._port.baudrate = baud
            self._found = ScanResult(self._found.url, baud, self._found.motors,
                                     self._found.seconds)
            self.plan = PollPlan(self.line_baud, self.motor_ids)

    def _set_parity(self, k82: int) -> None:
        if self._found.baud is not None:
            self._port.parity = "NEO"[k82 % 3]

    async def scan(self, bauds: tuple[int, ...] | None) -> dict[str, Any]:
        """Open the line again and scan it (docs/real-motor.md "Scan"); the motors found
        are the page's from now on.  When nothing answers the line stays as it was."""
        self._check_free()
        async with self._users_turn():
            self._held = "scan"
            await self._stop_poll()
            self.driver.close()
            try:
                with contextlib.suppress(Exception):
                    self._port.close()
                try:
                    opened, found = await asyncio.to_thread(open_line, self.url, bauds)
                except DeskError:                # the line as it was, opened again
                    self._port = StampedPort.wrap(
                        await asyncio.to_thread(open_port, self.url, self.line_baud))
                    raise
                self._port = StampedPort.wrap(opened)
                self._found = found
                self._values.clear()
                self.silent = None
                self.plan = PollPlan(self.line_baud, self.motor_ids)
            finally:
                self.session, self.driver = self._new_driver()
                self._held = None
                self.start()
        return {"lines": found.lines(), "summary": found.summary(), "motors": list(found.ids),
                "changed": True}

    # -- the poll ---------------------------------------------------------------------
    async def _poll(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            started = loop.time()
            try:
                await self._round()
                if self.silent is not None and not self.driver.failure:
                    self.silent = None
                    self._emit("message", "the motors answer again", 0, origin="web")
            except CoolMuscleTimeout as exc:
                if self.silent is None:
                    self.silent = (f"no answer from the motors ({exc}); a K20 change? "
                                   "Scan finds the rate")
                    self._emit("message", self.silent, 0, origin="web")
            except CoolMuscleError as exc:
                log.info("poll: %s", exc)
            self._rounds += 1
            for callback in list(self.on_round):
                try:
                    callback()
                except Exception:
                    log.exception("poll round callback failed")
            period = SILENT_RETRY if self.silent else self.plan.period
            await asyncio.sleep(max(0.0, started + period - loop.time()))

    async def _ask(self, motor: int, number: int, name: str) -> int:
        await self._no_user.wait()               # the user's requests first
        line = await self.driver.run(query(self.session, motor, f"?{number}.{motor}", name,
                                           POLL_TIMEOUT))
        return parse_int_reply(line, name, motor)

    async def _round(self) -> None:
        now = asyncio.get_running_loop().time()
        for motor in self.motor_ids:
            values = self.values(motor)
            if values.k23 is None:
                values.k23 = await self._k23(motor)
            values.position = await self._ask(motor, 96, "Px")
            values.speed = await self._ask(motor, 97, "Sx")
            values.torque = await self._ask(motor, 98, "Ix")
            reports = bool((values.k23 or 0) & Report.IN_POSITION_AND_ALARM)
            at_rest = values.status is not None and bool(
                values.status & (Ux.IN_POSITION | Ux.MOTOR_FREE | ALARM_BITS))
            if (not reports or values.status_due or values.status is None
                    or (at_rest and now - values.status_at >= STATUS_GUARD)):
                values.status_due = False
                values.status = await self._ask(motor, 99, "Ux")
                values.status_at = now
            if self._rounds % TEMPERATURE_EVERY == 0 or values.temperature is None:
                values.temperature = await self._ask(motor, 71, "Temp")

    async def _k23(self, motor: int) -> int:
        """``K23.n`` alone (ch. 3): whether the motor reports by itself."""
        await self._no_user.wait()
        line = await self.driver.run(query(self.session, motor, f"K23.{motor}", "K23",
                                           POLL_TIMEOUT))
        return parse_int_reply(line, "K23", motor)

    # -- events -------------------------------------------------------------------------
    def _on_event(self, event: MotorEvent) -> None:
        motor = event.motor or 0
        if event.kind == "status" and event.value is not None:
            values = self.values(motor)
            values.status, values.status_at = event.value, asyncio.get_running_loop().time()
            kind = "alarm" if event.value & ALARM_BITS else "status"
        elif event.kind in ("input", "output") and event.value is not None:
            if event.kind == "input":
                self.values(motor).inputs = event.value
            else:
                self.values(motor).outputs = event.value
            kind = event.kind
        elif event.kind in ("message", "error"):
            kind = "message"
        elif event.kind == "garbled":
            kind = "message"
        else:
            kind = "reply"
        self._emit(kind, event.text, motor, event.value)

