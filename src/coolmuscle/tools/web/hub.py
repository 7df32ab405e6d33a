"""The live feed of the dashboard: events to a console log, snapshots to the cards.

Owns what every open page receives, as JSON text frames:

* ``log``: every :class:`coolmuscle.device.Event` (replies, ``Ux`` reports, ``IN``/
  ``OUT`` reports, messages) with its virtual time and the line exactly as the host
  line prints it, plus the lines the pages sent (direction ``>``), in batches at
  most every ``LOG_PERIOD`` seconds;
* ``snap``: the snapshot of every motor of the chain (6.6 queries: ``?96`` ``?97``
  ``?98`` ``?99`` ``?70`` ``?50`` ``?71`` ``?74`` ...), sampled ``FAST_HZ`` times a second
  while anything changes and for a second after, ``IDLE_HZ`` times a second while
  nothing does, and sent only when a value changed (no polling storm when idle);
* ``tick``: the virtual time, once a second, so charts run on while nothing changes.

What is pending for a page goes out as one WebSocket message, one JSON frame a line
(JSON text holds no raw newline).  Each page has a bounded queue: a snapshot replaces the
unsent one, log lines beyond ``MAX_PENDING_LOG`` are dropped (the page is told how many), so
a slow page never holds up the motor or the other pages.
"""

from __future__ import annotations

import asyncio
import collections
import json
import logging
from collections.abc import Callable
from typing import Any, Protocol

from ...device import Event, MotorSnapshot

log = logging.getLogger(__name__)

FAST_HZ = 30.0
IDLE_HZ = 4.0
#: Seconds of fast sampling after the last change.
FAST_HOLD = 1.0
TICK_SECONDS = 1.0
HISTORY = 500
#: Seconds between two ``log`` frames: a host line busy with thousands of replies a
#: second costs the pages 1/LOG_PERIOD frames a second, not one frame per reply.
LOG_PERIOD = 0.05
MAX_PENDING_LOG = 2000

#: Columns of one motor's row in a ``snap`` frame (the page reads them by name).
#: Adds a line ``[time_ns, kind, text, motor, origin]`` to every page's console log.
Note = Callable[[list[Any]], None]

SNAP_FIELDS = ("id", "position", "target", "speed", "torque", "status", "inputs",
               "outputs", "temperature", "analog", "analog_out", "voltage",
               "position_error", "enabled")


class _Clock(Protocol):
    @property
    def now(self) -> int: ...


class FeedSource(Protocol):
    """What the feed reads: a :class:`~coolmuscle.device.Device`, or the line to a real
    motor (:class:`.line.LineDevice`, its clock the wall clock)."""

    @property
    def kernel(self) -> _Clock: ...

    @property
    def motor_ids(self) -> tuple[int, ...]: ...

    def snapshot(self, motor: int) -> MotorSnapshot: ...

    def subscribe(self, listener: Callable[[Event], None]) -> Callable[[], None]: ...


class Client:
    """One open page: its pending frames and the task that sends them."""

    def __init__(self, send: Callable[[str], Any]) -> None:
        self._send = send
        self.snap: str | None = None
        self.logs: collections.deque[tuple[str, int]] = collections.deque()
        self.log_lines = 0
        self.dropped = 0
        self.direct: collections.deque[str] = collections.deque(maxlen=256)
        self.wake = asyncio.Event()
        self.task: asyncio.Task[None] | None = None
        self.sent = 0
        #: log entries its ``hello`` history already held, still waiting in the batch
        self.seen: set[int] = set()

    def queue_log(self, frame: str, lines: int) -> None:
        """Queue an encoded ``log`` frame of ``lines`` lines; the oldest go past the bound."""
        self.logs.append((frame, lines))
        self.log_lines += lines
        while self.log_lines > MAX_PENDING_LOG and len(self.logs) > 1:
            _, cut = self.logs.popleft()
            self.log_lines -= cut
            self.dropped += cut
        self.wake.set()

    def queue_snap(self, frame: str) -> None:
        self.snap = frame
        self.wake.set()

    def queue_direct(self, frame: str) -> None:
        self.direct.append(frame)
        self.wake.set()

    async def run(self) -> None:
        """Send pending frames until cancelled or the socket fails (the page left)."""
        try:
            while True:
                await self.wake.wait()
                self.wake.clear()
                frames = self._take()
                if frames:                   # one WebSocket message, one frame a line
                    await self._send("\n".join(frames))
                    self.sent += 1
        except (ConnectionError, RuntimeError) as exc:
            log.debug("dashboard page gone: %s", exc)

    def _take(self) -> list[str]:
        frames = list(self.direct)
        self.direct.clear()
        if self.dropped:
            frames.append(json.dumps({"t": "log", "lines": [], "dropped": self.dropped}))
            self.dropped = 0
        frames.extend(frame for frame, _ in self.logs)
        self.logs.clear()
        self.log_lines = 0
        if self.snap is not None:
            frames.append(self.snap)
            self.snap = None
        return frames


class Hub:
    """Fan-out of the chain's events and snapshots to every open page."""

    def __init__(self, device: FeedSource, call: Callable[..., Any]) -> None:
        self.device = device
        self._call = call                     # runs a model call at "now" (Port.call)
        self.clients: set[Client] = set()
        self.history: collections.deque[list[Any]] = collections.deque(maxlen=HISTORY)
        self._batch: list[list[Any]] = []
        self._flush_scheduled = False
        self._last_rows: list[list[Any]] | None = None
        self._fast_until = 0.0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._task: asyncio.Task[None] | None = None
        self._unsubscribe: Callable[[], None] | None = None
        self.samples = 0

    # -- life cycle ---------------------------------------------------------
    def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._unsubscribe = self.device.subscribe(self._on_event)
        self._task = asyncio.create_task(self._sampler(), name="coolmuscle-web-sampler")

    async def close(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        tasks = [c.task for c in self.clients if c.task is not None]
        if self._task is not None:
            tasks.append(self._task)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        self._task = None
        self.clients.clear()

    def pending(self) -> set[int]:
        """The log entries queued but not yet sent (their ids): a page greeted now has
        them in its history already (:meth:`add`)."""
        return {id(entry) for entry in self._batch}

    def add(self, client: Client, seen: set[int] | None = None) -> None:
        """A page joins; ``seen``: entries of the pending batch its history held."""
        client.seen = set(seen or ())
        self.clients.add(client)
        client.task = asyncio.create_task(client.run(), name="coolmuscle-web-client")
        self.changed()

    def remove(self, client: Client) -> None:
        self.clients.discard(client)
        if client.task is not None:
            client.task.cancel()

    # -- log ------------------------------------------------------------------
    def _on_event(self, event: Event) -> None:
        self.add_log([event.time, event.kind, event.text, event.motor, event.origin])
        self.changed()

    def add_log(self, entry: list[Any]) -> None:
        """Queue one log entry ``[time_ns, kind_or_>, text, motor, origin]`` for every page."""
        self.history.append(entry)
        self._batch.append(entry)
        if not self._flush_scheduled and self._loop is not None:
            self._flush_scheduled = True
            self._loop.call_later(LOG_PERIOD, self._flush)

    def _flush(self) -> None:
        """One ``log`` frame for every page, encoded once, at most 1/LOG_PERIOD a second."""
        self._flush_scheduled = False
        batch, self._batch = self._batch, []
        if not batch or not self.clients:
            return
        frame = json.dumps({"t": "log", "lines": batch, "dropped": 0}, separators=(",", ":"))
        for client in self.clients:
            if client.seen:                 # greeted during this batch: not twice
                lines = [entry for entry in batch if id(entry) not in client.seen]
                client.seen = set()
                if lines:
                    client.queue_log(json.dumps({"t": "log", "lines": lines, "dropped": 0},
                                                separators=(",", ":")), len(lines))
                continue
            client.queue_log(frame, len(batch))

    # -- snapshots ----------------------------------------------------------------
    def changed(self) -> None:
        """Something may move now: sample fast for a while."""
        if self._loop is not None:
            self._fast_until = self._loop.time() + FAST_HOLD

    def rows(self) -> list[list[Any]]:
        """One row per motor (``SNAP_FIELDS``), read at the current virtual instant."""
        out = []
        for motor_id in self.device.motor_ids:
            s = self.device.snapshot(motor_id)
            out.append([s.motor, s.position, s.target, s.speed, s.torque, s.status,
                        s.inputs, s.outputs, s.temperature, s.analog,
                        s.extra.get("analog_output", 0), s.voltage, s.position_error,
                        bool(s.enabled)])
        return out

    def snapshot_frame(self) -> str:
        """The ``snap`` frame now, whether or not anything changed."""
        rows = self._call(self.rows)
        self._last_rows = rows
        return self._frame(rows)

    def _frame(self, rows: list[list[Any]]) -> str:
        return json.dumps({"t": "snap", "time": self.device.kernel.now, "m": rows},
                          separators=(",", ":"))

    async def _sampler(self) -> None:
        """Sample on a fixed grid of deadlines, so a busy loop does not lower the rate."""
        assert self._loop is not None
        next_tick = 0.0
        due = self._loop.time()
        while True:
            now = self._loop.time()
            fast = now < self._fast_until
            due = max(due + 1.0 / (FAST_HZ if fast else IDLE_HZ), now + 0.002)
            await asyncio.sleep(due - now)
            if not self.clients:
                continue
            try:
                self._sample_once()
            except Exception:          # a model failure must not end the feed
                log.exception("dashboard sampling failed")
            if self._loop.time() >= next_tick:
                next_tick = self._loop.time() + TICK_SECONDS
                self.broadcast(json.dumps({"t": "tick", "time": self.device.kernel.now}))

    def _sample_once(self) -> None:
        rows = self._call(self.rows)
        self.samples += 1
        if rows == self._last_rows:
            return
        self._last_rows = rows
        self.changed()
        frame = self._frame(rows)
        for client in self.clients:
            client.queue_snap(frame)

    def broadcast(self, frame: str) -> None:
        """Send ``frame`` to every page (ahead of its pending log lines and snapshot)."""
        for client in self.clients:
            client.queue_direct(frame)
