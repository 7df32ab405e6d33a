"""The pages' requests take turns, as the host line's clients do (docs/web.md "Fair
share", docs/reliability.md).

Each open page has a bounded queue of requests (:class:`PageRequests`,
``MAX_QUEUED`` of them); one more is refused at once with a message, never queued.
Reading the pages' messages is bounded too: at most ``MAX_PER_WAKE`` messages of all
pages together per wake-up (:meth:`Turns.read_turn`), so pages flooding refused
requests cost the loop little more than pages that wait for their answers.
The :class:`Turns` of a dashboard runs the queues round robin, one request of each page
per turn, and at most ``MAX_PER_WAKE`` requests or ``MAX_SECONDS_PER_WAKE`` of them per
wake-up of the event loop (the bound Modbus TCP has): the rest run at the next wake-up,
after the host line's clients, the other front ends and the motor's own time.  A page
pipelining thousands of console lines therefore delays a host-line client by one
wake-up's worth at most, not by its whole backlog.

A request that does its work in steps (a bank upload: checked in a worker thread, then
sent in slices, :mod:`.banks`) runs as a task of its own; the page's next request waits
for it (a page's answers keep the order of its requests), the other pages go on.

When a page leaves, what it queued is dropped (counted), not run; a request already
running ends normally.

Pure work (checking a bank text, drawing a plot) runs in a worker thread
(:func:`in_worker`); while one runs the interpreter hands the processor between threads
every ``WORKER_SWITCH_INTERVAL`` seconds instead of Python's 5 ms, so the loop's thread,
which gives the interpreter up at each socket call, gets it back within a millisecond.
"""

from __future__ import annotations

import asyncio
import sys
import threading
import time
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

#: Requests one page may have waiting; one more is refused with a message.
MAX_QUEUED = 64
#: Requests run per wake-up of the event loop, and wall time, before the others' turn.
MAX_PER_WAKE = 32
MAX_SECONDS_PER_WAKE = 0.01

#: The interpreter's switch interval (s) while a worker thread does a page's pure work.
WORKER_SWITCH_INTERVAL = 0.001

T = TypeVar("T")
Answer = dict[str, Any]
#: Runs one request now: its answer, or an awaitable of it (a request in steps).
Handler = Callable[[Any], "Answer | Awaitable[Answer]"]


class PageRequests:
    """One page's queue: its requests, where their answers go, and whether its
    connection is gone (``gone``: then nothing more of it runs)."""

    def __init__(self, answer: Callable[[Answer], None],
                 gone: Callable[[], bool] = lambda: False) -> None:
        self.answer = answer
        self.gone = gone
        self.queue: deque[Any] = deque()
        self.busy = False            # a request in steps is running
        self.closed = False
        self.peak = 0                # most requests ever waiting (tests, reports)


class Turns:
    """Round robin over the pages' queues with a bound per wake-up (module docstring).

    ``handle`` runs one request: it returns the answer, or an awaitable of it for a
    request that runs in steps (run as a task; the page waits for it)."""

    def __init__(self, handle: Handler, *, max_queued: int = MAX_QUEUED,
                 max_per_wake: int = MAX_PER_WAKE,
                 seconds_per_wake: float = MAX_SECONDS_PER_WAKE) -> None:
        self.handle = handle
        self.max_queued = max_queued
        self.max_per_wake = max_per_wake
        self.seconds_per_wake = seconds_per_wake
        self._ready: deque[PageRequests] = deque()
        self._scheduled = False
        self._tasks: set[asyncio.Task[None]] = set()
        self._reads = 0              # messages read in this wake-up
        self._reads_reset = False
        self.ran = 0                 # requests run
        self.refused = 0             # refused: the page's queue was full
        self.dropped = 0             # queued by pages that left, never run
        self.wakeups = 0             # wake-ups that ran requests
        self.most_per_wake = 0       # most requests run in one wake-up

    def open(self, answer: Callable[[Answer], None],
             gone: Callable[[], bool] = lambda: False) -> PageRequests:
        """A page joined: its queue (answers go to ``answer``; ``gone`` says its
        connection was lost before its close was read)."""
        return PageRequests(answer, gone)

    def submit(self, page: PageRequests, request: Any) -> bool:
        """Queue ``request`` of ``page``; ``False`` (not queued) when its queue is full."""
        if page.closed:
            return False
        if len(page.queue) >= self.max_queued:
            self.refused += 1
            return False
        page.queue.append(request)
        page.peak = max(page.peak, len(page.queue))
        if not page.busy and page not in self._ready:
            self._ready.append(page)
        self._schedule()
        return True

    async def read_turn(self) -> None:
        """A page's message was read: pause until the next wake-up once the pages have
        read ``max_per_wake`` messages in this one."""
        self._reads += 1
        if not self._reads_reset:
            self._reads_reset = True
            asyncio.get_running_loop().call_soon(self._reset_reads)
        if self._reads >= self.max_per_wake:
            await asyncio.sleep(0)

    def _reset_reads(self) -> None:
        self._reads, self._reads_reset = 0, False

    def close(self, page: PageRequests) -> None:
        """The page left: what it queued is dropped, not run."""
        page.closed = True
        self.dropped += len(page.queue)
        page.queue.clear()
        if page in self._ready:
            self._ready.remove(page)

    async def close_all(self) -> None:
        """Cancel the requests in steps still running (the server stops)."""
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

    # -- the turns ----------------------------------------------------------------------
    def _schedule(self) -> None:
        """The next turn, as a timer due now rather than ``call_soon``: the loop runs it
        after the I/O of its next wake-up and after the callbacks already waiting (a
        host-line reply about to be written goes out first, not one turn later)."""
        if not self._scheduled and self._ready:
            self._scheduled = True
            asyncio.get_running_loop().call_later(0, self._run)

    def _run(self) -> None:
        """One wake-up: each ready page runs one request in turn, within the bound."""
        self._scheduled = False
        deadline = time.perf_counter() + self.seconds_per_wake
        ran = 0
        while self._ready and ran < self.max_per_wake:
            page = self._ready.popleft()
            if not page.closed and page.gone():
                self.close(page)
            if page.closed or page.busy or not page.queue:
                continue
            self._one(page, page.queue.popleft())
            ran += 1
            if page.queue and not page.busy:
                self._ready.append(page)
            if time.perf_counter() > deadline:
                break
        if ran:
            self.wakeups += 1
            self.most_per_wake = max(self.most_per_wake, ran)
        self._schedule()

    def _one(self, page: PageRequests, request: Any) -> None:
        self.ran += 1
        answer = self.handle(request)
        if isinstance(answer, dict):
            page.answer(answer)
            return
        page.busy = True
        task = asyncio.ensure_future(self._steps(page, answer))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _steps(self, page: PageRequests, answer: Awaitable[Answer]) -> None:
        try:
            page.answer(await answer)
        finally:
            page.busy = False
            if page.queue and not page.closed and page not in self._ready:
                self._ready.append(page)
                self._schedule()


class _SwitchInterval:
    """The switch interval lowered while any worker runs, restored after the last one
    (process-wide: a lock, as several servers may run in one process)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._workers = 0
        self._saved = 0.0

    def enter(self) -> None:
        with self._lock:
            if not self._workers:
                self._saved = sys.getswitchinterval()
                sys.setswitchinterval(min(self._saved, WORKER_SWITCH_INTERVAL))
            self._workers += 1

    def leave(self) -> None:
        with self._lock:
            self._workers -= 1
            if not self._workers:
                sys.setswitchinterval(self._saved)


_SWITCH = _SwitchInterval()


async def in_worker(fn: Callable[..., T], *args: Any) -> T:
    """``fn(*args)`` in a worker thread (pure work: no model state), the switch interval
    lowered meanwhile (module docstring)."""
    _SWITCH.enter()
    try:
        return await asyncio.to_thread(fn, *args)
    finally:
        _SWITCH.leave()
