"""The deterministic simulation kernel: it owns virtual time.

Time is an integer count of nanoseconds (``Kernel.now``), so that ordering and
arithmetic are exact and every run is the same.  Nothing in the motor model reads
the wall clock; every delay goes through :meth:`Kernel.schedule`.

The event queue is a heap of ``(time, priority, counter, timer)``: the counter
makes the order of events at the same instant and priority deterministic (the
order they were scheduled in).  Motion is closed-form (see
:mod:`coolmuscle.motor.motion.profile`), so the kernel jumps from event to event and
never ticks when nothing is scheduled.

Real-time pacing is a thin layer on top (:mod:`coolmuscle.sim.realtime`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from heapq import heappop, heappush
from typing import Final

from mypy_extensions import mypyc_attr

log = logging.getLogger(__name__)

NS_PER_S: Final = 1_000_000_000
NS_PER_MS: Final = 1_000_000
NS_PER_US: Final = 1_000

#: Priorities for events that fall on the same instant (lower runs first).
PRIO_IO: Final = 0        # input edges, bytes arriving on a line
PRIO_HORIZON: Final = 5   # a motion solved in part reaches its frontier (after the new target)
PRIO_MOTION: Final = 10   # motion milestones (end of move, passing points, alarms)
PRIO_LOGIC: Final = 20    # program bank steps, ladder scans
PRIO_REPORT: Final = 30   # output delivery

Callback = Callable[[], None]


def nearest(x: float) -> int:
    """``round(x)``: the nearest integer, a tie to the even one.  Written out: compiled,
    ``round`` is a generic call (the builtin looked up by name, the float boxed)."""
    below = math.floor(x)
    rest = x - below                      # exact: below is within 1 of x
    if rest > 0.5 or (rest == 0.5 and below % 2 == 1):
        return below + 1
    return below


def seconds(s: float) -> int:
    """Convert seconds (float) to kernel nanoseconds, rounding to nearest."""
    return nearest(s * NS_PER_S)


def ms(value: float) -> int:
    """Convert milliseconds to kernel nanoseconds."""
    return nearest(value * NS_PER_MS)


def to_seconds(ns: int) -> float:
    """Convert kernel nanoseconds to float seconds."""
    return ns / NS_PER_S


@dataclass(init=False, eq=False, slots=True)
class Timer:
    """A scheduled callback; :meth:`cancel` keeps it from running."""

    at: int
    callback: Callback
    name: str
    cancelled: bool

    def __init__(self, at: int, callback: Callback, name: str = "",
                 cancelled: bool = False) -> None:
        # written out: built on the hot path (docs/architecture.md "Fast code")
        self.at = at
        self.callback = callback
        self.name = name
        self.cancelled = cancelled

    def cancel(self) -> None:
        """Cancel the timer; cancelling twice or after it ran is harmless."""
        self.cancelled = True

    @property
    def active(self) -> bool:
        return not self.cancelled


class _Shared:
    """The callbacks given for one instant and priority (:meth:`Kernel.schedule_shared`),
    run by one event in the order they were given."""

    __slots__ = ("kernel", "key", "calls")

    def __init__(self, kernel: Kernel, key: tuple[int, int]) -> None:
        self.kernel = kernel
        self.key = key
        self.calls: list[Callback] = []

    def __call__(self) -> None:
        kernel, (at, priority) = self.kernel, self.key
        del kernel._shared[self.key]           # one given from here on gets an event of its own
        calls = self.calls
        for i, call in enumerate(calls):
            try:
                call()
            except BaseException:
                # the others still run, as they would have with an event each
                for rest in calls[i + 1:]:
                    kernel.schedule_shared(at, rest, priority=priority)
                raise


@mypyc_attr(allow_interpreted_subclasses=True)   # compiled (coolmuscle/_accel.py); subclassable
class Kernel:
    """Virtual-time event kernel: ``now``, ``schedule``, ``peek``, ``step``, ``run``."""

    def __init__(self, start: float = 0) -> None:
        #: Current virtual time in nanoseconds (read it; only the kernel moves it).  A
        #: plain attribute, not a property: the model reads it dozens of times a move.
        self.now: int = int(start)
        self._queue: list[tuple[int, int, int, Timer]] = []
        self._scheduled = 0             # events scheduled so far: ties run in that order
        self._events_run = 0
        self._observers: list[Callback] = []
        self._shared: dict[tuple[int, int], _Shared] = {}

    # -- time -----------------------------------------------------------
    @property
    def now_s(self) -> float:
        """Current virtual time in seconds."""
        return self.now / NS_PER_S

    @property
    def events_run(self) -> int:
        """How many callbacks have run (for benchmarks)."""
        return self._events_run

    # -- scheduling -----------------------------------------------------
    def schedule(self, delay: float, callback: Callback, *, priority: int = PRIO_MOTION,
                 name: str = "") -> Timer:
        """Run ``callback`` ``delay`` nanoseconds from now (``delay`` >= 0)."""
        if delay < 0:
            raise ValueError(f"negative delay {delay}")
        return self.schedule_at(self.now + int(delay), callback, priority=priority, name=name)

    def schedule_at(self, at: float, callback: Callback, *, priority: int = PRIO_MOTION,
                    name: str = "") -> Timer:
        """Run ``callback`` at absolute time ``at`` (not before now)."""
        when = max(int(at), self.now)
        timer = Timer(when, callback, name)
        self._scheduled += 1
        heappush(self._queue, (when, priority, self._scheduled, timer))
        return timer

    def schedule_shared(self, at: int, callback: Callback, *, priority: int,
                        name: str = "") -> None:
        """Run ``callback`` at ``at`` (not before now) in one event with every other
        callback given for that instant and priority, in the order they were given.
        It cannot be cancelled: the callback looks whether it is still due.  Many
        objects waiting for the same instant (the axes of a fieldbus cycle) cost one
        event, not one each."""
        key = (max(int(at), self.now), priority)
        shared = self._shared.get(key)
        if shared is None:
            shared = self._shared[key] = _Shared(self, key)
            self.schedule_at(key[0], shared, priority=priority, name=name)
        shared.calls.append(callback)

    def call_soon(self, callback: Callback, *, priority: int = PRIO_LOGIC, name: str = "") -> Timer:
        """Run ``callback`` at the current instant, after what is already due now."""
        return self.schedule_at(self.now, callback, priority=priority, name=name)

    def add_observer(self, observer: Callback) -> Callable[[], None]:
        """Call ``observer()`` after every event (trace recorders); returns a remover."""
        self._observers.append(observer)

        def remove() -> None:
            if observer in self._observers:
                self._observers.remove(observer)
        return remove

    # -- running --------------------------------------------------------
    def _drop_cancelled(self) -> None:
        while self._queue and self._queue[0][3].cancelled:
            heappop(self._queue)

    def peek(self) -> int | None:
        """Time of the next pending event, or ``None`` when nothing is scheduled."""
        self._drop_cancelled()
        return self._queue[0][0] if self._queue else None

    def step(self) -> bool:
        """Run the next event; return ``False`` when the queue is empty."""
        self._drop_cancelled()
        if not self._queue:
            return False
        at, _prio, _count, timer = heappop(self._queue)
        self.now = at
        timer.cancelled = True
        self._events_run += 1
        timer.callback()
        for observer in self._observers:
            observer()
        return True

    def run(self, until: float | None = None, *, max_events: int | None = None) -> int:
        """Run events up to and including time ``until`` and leave ``now == until``.

        With ``until=None`` it runs until the queue is empty (beware endless
        periodic events; pass ``max_events`` to bound it).  Returns the number of
        events run.
        """
        count = 0
        if until is not None:
            until = int(until)             # whole nanoseconds (a float is floored)
        queue, pop, observers = self._queue, heappop, self._observers
        while queue:                       # peek() and step() written out: the hot loop
            at, _prio, _count, timer = queue[0]
            if timer.cancelled:
                pop(queue)
                continue
            if until is not None and at > until:
                break
            if max_events is not None and count >= max_events:
                return count
            pop(queue)
            self.now = at
            timer.cancelled = True
            self._events_run += 1
            timer.callback()
            for observer in observers:
                observer()
            count += 1
        if until is not None and until > self.now:
            self.now = int(until)
        return count

    def advance(self, delay: float) -> int:
        """Run everything due within the next ``delay`` nanoseconds."""
        return self.run(self.now + int(delay))

    def run_until(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Run events until ``predicate()`` is true or ``timeout`` ns pass.

        The predicate is checked after every event.  Returns whether it became
        true; on timeout, ``now`` is the deadline.
        """
        deadline = self.now + int(timeout)
        if predicate():
            return True
        while True:
            nxt = self.peek()
            if nxt is None or nxt > deadline:
                self.now = max(self.now, deadline)
                return predicate()
            self.step()
            if predicate():
                return True
