"""Pacing virtual time to the wall clock: the thin real-time layer over the kernel.

This module owns the mapping from the wall clock (``time.monotonic``) to kernel
time, optionally scaled, and the rule every real-time front end follows:

* before any input is delivered, the kernel is run up to "now"
  (:meth:`RealtimeClock.catch_up`), so the input arrives at the virtual instant
  that matches the wall clock;
* between inputs, the driver sleeps until the wall time of the next kernel event
  or until it is woken by input (:class:`RealtimeDriver` under asyncio; the
  pyserial URL handler does the same with a ``threading.Condition``); a precise
  driver hands short waits to a :class:`PreciseWaker` (epoll sleeps in whole
  milliseconds);
* it reports falling behind: how late (wall seconds) the most overdue event ran.

:class:`FastClock` is the unpaced mode (``coolmuscle run``, ``coolmuscle://?mode=fast``):
virtual time moves only when the caller advances it, as fast as the CPU allows.

The model never imports this module (docs/architecture.md rule 1); it only sees
``Kernel.now``.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

from .kernel import NS_PER_S, Kernel

log = logging.getLogger(__name__)

T = TypeVar("T")

#: Lateness (wall seconds) above which an event counts as "behind".
DEFAULT_BEHIND_THRESHOLD = 0.05

#: Minimum wall seconds between two "falling behind" warnings from one driver.
BEHIND_LOG_INTERVAL = 5.0

BehindCallback = Callable[[float], None]

#: A precise driver hands waits shorter than this to its :class:`PreciseWaker`.
PRECISE_BELOW = 0.005


class RealtimeClock:
    """Maps the wall clock to kernel time and keeps the kernel caught up.

    Virtual time is ``v0 + (wall - w0) * scale`` where ``(w0, v0)`` is the anchor
    taken at construction (or :meth:`anchor`).  ``scale`` is virtual seconds per
    wall second (``2.0`` runs the motor twice as fast as life).  If something
    else advanced the kernel beyond the mapped time (a fast-mode caller, a test),
    the clock re-anchors so virtual time never runs backwards.

    Not thread-safe by itself: callers serialise access (the asyncio loop, or the
    URL handler's lock).
    """

    paced = True

    def __init__(self, kernel: Kernel, *, scale: float = 1.0,
                 clock: Callable[[], float] = time.monotonic,
                 behind_threshold: float = DEFAULT_BEHIND_THRESHOLD,
                 on_behind: BehindCallback | None = None) -> None:
        if not (scale > 0 and math.isfinite(scale)):
            raise ValueError(f"time scale must be a positive number, not {scale!r}")
        self.kernel = kernel
        self.scale = float(scale)
        self._clock = clock
        self.behind_threshold = behind_threshold
        self.on_behind = on_behind
        self.last_lag = 0.0   # wall seconds the most overdue event of the last catch-up ran late
        self.max_lag = 0.0
        self.late_count = 0   # catch-ups that ran an event later than the threshold
        self.errors = 0       # kernel events that raised
        self.anchor()

    # -- mapping --------------------------------------------------------
    def anchor(self) -> None:
        """Make "now" on the wall clock correspond to the kernel's current time."""
        self._w0 = self._clock()
        self._v0 = self.kernel.now

    def virtual_at(self, wall: float) -> int:
        """Kernel time (ns) that corresponds to wall-clock time ``wall``."""
        return self._v0 + round((wall - self._w0) * self.scale * NS_PER_S)

    def wall_at(self, virtual: int) -> float:
        """Wall-clock time at which kernel time ``virtual`` is reached."""
        return self._w0 + (virtual - self._v0) / (self.scale * NS_PER_S)

    def lateness(self, virtual: int) -> float:
        """Wall seconds since kernel time ``virtual`` was due (negative: still to come)."""
        return self._clock() - self.wall_at(virtual)

    def virtual_now(self) -> int:
        """Kernel time that corresponds to the wall clock now (never before ``kernel.now``)."""
        target = self.virtual_at(self._clock())
        if target < self.kernel.now:
            self.anchor()
            return self.kernel.now
        return target

    # -- driving --------------------------------------------------------
    def catch_up(self) -> int:
        """Run every event due by the wall clock now and leave ``kernel.now`` at "now".

        An event that raises (a model bug) is logged and counted in ``errors``; the
        events after it still run, so one failure never stops virtual time.
        """
        target = self.virtual_now()
        first = self.kernel.peek()
        count = 0
        while True:
            try:
                count += self.kernel.run(until=target)
                break
            except Exception:
                self.errors += 1
                log.exception("a kernel event failed at %d ns; virtual time goes on",
                              self.kernel.now)
        if first is not None and first <= target:
            lag = self._clock() - self.wall_at(first)
            self._note_lag(lag)
        else:
            self.last_lag = 0.0
        return count

    def _note_lag(self, lag: float) -> None:
        self.last_lag = max(lag, 0.0)
        self.max_lag = max(self.max_lag, self.last_lag)
        if self.last_lag > self.behind_threshold:
            self.late_count += 1
            if self.on_behind is not None:
                self.on_behind(self.last_lag)

    def seconds_until_next(self) -> float | None:
        """Wall seconds until the next event is due (0.0 if overdue, None if none)."""
        nxt = self.kernel.peek()
        if nxt is None:
            return None
        return max(0.0, self.wall_at(nxt) - self._clock())


class FastClock:
    """Unpaced virtual time: it moves only when :meth:`advance` / :meth:`run_until` say so.

    Runs are deterministic: the same inputs at the same virtual instants give the
    same bytes, whatever the machine's speed.
    """

    paced = False

    def __init__(self, kernel: Kernel) -> None:
        self.kernel = kernel

    def catch_up(self) -> int:
        """Nothing to do: time does not follow the wall clock."""
        return 0

    def seconds_until_next(self) -> float | None:
        """Never sleep for kernel events: they run when time is advanced."""
        return None

    def advance(self, delay_ns: int) -> int:
        """Run everything due within the next ``delay_ns`` nanoseconds, instantly."""
        return self.kernel.advance(delay_ns)

    def run_until(self, predicate: Callable[[], bool], timeout_ns: int) -> bool:
        """Advance until ``predicate()`` holds or ``timeout_ns`` of virtual time passed."""
        return self.kernel.run_until(predicate, timeout_ns)


def make_clock(kernel: Kernel, mode: str = "realtime", *,
               scale: float = 1.0) -> RealtimeClock | FastClock:
    """``"realtime"`` -> :class:`RealtimeClock`, ``"fast"`` -> :class:`FastClock`."""
    if mode == "realtime":
        return RealtimeClock(kernel, scale=scale)
    if mode == "fast":
        return FastClock(kernel)
    raise ValueError(f"unknown time mode {mode!r} (expected 'realtime' or 'fast')")


class PreciseWaker:
    """Wakes an asyncio loop at a wall-clock instant, within about 0.1-0.2 ms.

    asyncio sleeps in its selector, and epoll rounds every timeout up to the next
    millisecond: a timer 0.3 ms away fires up to 1 ms late.  This thread sleeps on a
    condition instead (``time.monotonic`` deadline, microsecond resolution) and wakes
    the loop through its self-pipe (``call_soon_threadsafe``); the loop resumes about
    0.1-0.2 ms after the deadline (timer slack, the self-pipe, the GIL; measured p50
    157 us, p99 233 us on the 2-CPU development machine).  For front ends with a
    cycle of their own (the EtherCAT bridge's 1 ms, :attr:`RealtimeDriver.precise`).
    """

    def __init__(self, loop: asyncio.AbstractEventLoop, callback: Callable[[], Any]) -> None:
        self._loop = loop
        self._callback = callback
        self._cond = threading.Condition()
        self._deadline: float | None = None
        self._closed = False
        self.wakes = 0
        self._thread = threading.Thread(target=self._run, name="coolmuscle-waker",
                                        daemon=True)
        self._thread.start()

    def arm(self, deadline: float) -> None:
        """Call back in the loop at ``time.monotonic()`` = ``deadline`` (replaces the last)."""
        with self._cond:
            self._deadline = deadline
            self._cond.notify()

    def disarm(self) -> None:
        with self._cond:
            if self._deadline is not None:    # already fired: nothing to wake the thread for
                self._deadline = None
                self._cond.notify()

    def _run(self) -> None:
        with self._cond:
            while not self._closed:
                deadline = self._deadline
                if deadline is None:
                    self._cond.wait()
                    continue
                remaining = deadline - time.monotonic()
                if remaining > 0:
                    self._cond.wait(remaining)
                    continue
                self._deadline = None
                self.wakes += 1
                try:
                    self._loop.call_soon_threadsafe(self._callback)
                except RuntimeError:              # the loop is closed: nothing to wake
                    return

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify()
        if self._thread is not threading.current_thread():
            self._thread.join(1.0)


class RealtimeDriver:
    """Runs a kernel in step with the wall clock inside an asyncio event loop.

    Front ends deliver input with :meth:`call` (or :meth:`feed`): the kernel is
    caught up first, the callback runs at the matching virtual instant, and the
    loop is woken to re-plan its sleep (the input may have scheduled events).
    Everything touching the model must run in the loop's thread.
    """

    def __init__(self, kernel: Kernel, *, scale: float = 1.0,
                 clock: Callable[[], float] = time.monotonic,
                 behind_threshold: float = DEFAULT_BEHIND_THRESHOLD,
                 on_behind: BehindCallback | None = None) -> None:
        self.kernel = kernel
        self.clock = RealtimeClock(kernel, scale=scale, clock=clock,
                                   behind_threshold=behind_threshold,
                                   on_behind=self._behind)
        self._user_on_behind = on_behind
        self._last_behind_log = -math.inf
        self._wall = clock
        self._wake: asyncio.Event | None = None
        self._stopped = False
        self.running = False
        #: Wake for kernel events within about 0.1-0.2 ms, not the selector's whole
        #: millisecond (:class:`PreciseWaker`); a front end with its own cycle sets it.
        self.precise = False
        self.waker: PreciseWaker | None = None     # made at the first precise wait

    # -- input ----------------------------------------------------------
    def call(self, fn: Callable[..., T], *args: Any) -> T:
        """Catch up, run ``fn(*args)`` at the current virtual instant, wake the loop."""
        self.clock.catch_up()
        try:
            return fn(*args)
        finally:
            self.wake()

    def feed(self, host_line: Any, data: bytes) -> None:
        """Deliver bytes from the host to ``host_line`` at the wall-clock instant now."""
        self.call(host_line.feed, data)

    def wake(self) -> None:
        """Make the loop re-plan its sleep (new events may be due earlier)."""
        if self._wake is not None:
            self._wake.set()

    # -- the loop -------------------------------------------------------
    async def run(self) -> None:
        """Keep the kernel in step with the wall clock until :meth:`stop`."""
        loop = asyncio.get_running_loop()
        wake = self._wake = asyncio.Event()
        self.running = True
        self.clock.anchor()
        waker = self.waker = None
        try:
            while not self._stopped:
                wake.clear()  # before catching up: a wake-up from an event is kept
                self.clock.catch_up()
                if self._stopped:
                    break
                delay = self.clock.seconds_until_next()
                if delay is not None and delay <= 0:
                    await asyncio.sleep(0)  # let I/O in between overdue events
                    continue
                handle = None
                if delay is not None and self.precise and delay < PRECISE_BELOW:
                    if waker is None:
                        waker = self.waker = PreciseWaker(loop, wake.set)
                    waker.arm(time.monotonic() + delay)
                elif delay is not None:
                    handle = loop.call_later(delay, wake.set)
                try:
                    await wake.wait()
                finally:
                    if handle is not None:
                        handle.cancel()
                    if waker is not None:
                        waker.disarm()
        finally:
            self.running = False
            if waker is not None:
                waker.close()

    def stop(self) -> None:
        """Ask :meth:`run` to return (at once if it has not started yet; final)."""
        self._stopped = True
        self.wake()

    # -- lag ------------------------------------------------------------
    def _behind(self, lag: float) -> None:
        if self._user_on_behind is not None:
            self._user_on_behind(lag)
        now = self._wall()
        if now - self._last_behind_log >= BEHIND_LOG_INTERVAL:
            self._last_behind_log = now
            log.warning("virtual time is falling behind the wall clock: an event ran %.1f ms late",
                        lag * 1000)

    @property
    def max_lag(self) -> float:
        """Largest lateness seen so far (wall seconds)."""
        return self.clock.max_lag
