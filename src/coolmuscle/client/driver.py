"""The blocking driver: runs sans-IO operations over a pyserial port.

:class:`SyncDriver` executes the requests an operation yields
(:mod:`coolmuscle.client.ops`) on any pyserial port: a real serial port, ``socket://``,
``coolmuscle://`` (in-process simulator), ``loop://``.  It owns the port reads and
writes, the deadlines and the delivery of events to subscribers.  Every wait is
bounded: an :class:`~coolmuscle.client.protocol.Exchange` that is not answered in its
timeout raises :class:`~coolmuscle.errors.CoolMuscleTimeout`; a failing port raises
:class:`~coolmuscle.errors.TransportError`.

Clock: wall time, except on a ``coolmuscle://?mode=fast`` port, where time moves only
while the client reads: there a timeout is counted in the motor's virtual seconds (a
5 s wait takes no wall time), with the wall clock as a backstop.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

from serial import SerialException

from ..errors import CoolMuscleError, CoolMuscleTimeout, TransportError
from .ops import Listen, Now, Op, Pause, Session, T
from .protocol import Exchange, MotorEvent

log = logging.getLogger(__name__)

__all__ = ["SyncDriver", "Listener", "port_clock"]

#: Longest single blocking read; a longer wait is several reads.
READ_SLICE = 0.25

Listener = Callable[[MotorEvent], None]


def port_clock(port: Any) -> tuple[Callable[[], float], bool]:
    """``(now, virtual)``: the clock that timeouts on ``port`` are counted in."""
    kernel = getattr(port, "kernel", None)
    options = getattr(port, "options", None) or {}
    if kernel is not None and options.get("mode") == "fast":
        return (lambda: port.kernel.now / 1e9 if port.kernel is not None else 0.0), True
    return time.monotonic, False


class _Deadline:
    """A timeout on the port's clock, with the wall clock as a backstop."""

    def __init__(self, clock: Callable[[], float], virtual: bool, seconds: float) -> None:
        self._clock = clock
        self._end = clock() + seconds
        self._wall_end = time.monotonic() + (seconds + 5.0 if virtual else seconds)
        self._virtual = virtual

    def remaining(self) -> float:
        left = self._end - self._clock()
        if self._virtual:
            if left < 1e-6:  # the kernel counts whole ns: less cannot be waited for
                return 0.0
            left = min(left, self._wall_end - time.monotonic())
        return left


class SyncDriver:
    """Runs operations on a port; one at a time (a lock makes it thread-safe)."""

    def __init__(self, port: Any, session: Session) -> None:
        self.port = port
        self.session = session
        self.now, self.virtual = port_clock(port)
        self.listeners: list[tuple[Listener, Callable[[MotorEvent], bool]]] = []
        self.lock = threading.RLock()
        #: threads waiting for ``lock`` in :meth:`turn` (a wait makes way only for them)
        self._contenders: collections.deque[None] = collections.deque()
        self._drain_by_timeout = type(port).__module__.endswith("protocol_socket")

    # -- running operations ------------------------------------------------------
    @contextlib.contextmanager
    def turn(self) -> Iterator[None]:
        """Hold the connection for one operation (threads take turns)."""
        self._contenders.append(None)       # deque append/pop: atomic, no lock needed
        try:
            self.lock.acquire()
        finally:
            self._contenders.pop()
        try:
            yield
        finally:
            self.lock.release()

    def run(self, op: Op[T]) -> T:
        """Drive ``op`` to its end; its exceptions propagate."""
        with self.turn():
            result: Any = None
            error: BaseException | None = None
            while True:
                try:
                    request = op.throw(error) if error is not None else op.send(result)
                except StopIteration as stop:
                    return stop.value  # type: ignore[no-any-return]
                result, error = None, None
                try:
                    result = self._do(request)
                except CoolMuscleError as exc:
                    error = exc

    def _do(self, request: Any) -> Any:
        if isinstance(request, Exchange):
            return self._exchange(request)
        if isinstance(request, Listen):
            return self._listen(request)
        if isinstance(request, Pause):
            self._pump_for(request.seconds, shared=request.shared)
            return None
        if isinstance(request, Now):
            return self.now()
        raise TypeError(f"unknown request {request!r}")

    def _deadline(self, seconds: float) -> _Deadline:
        return _Deadline(self.now, self.virtual, seconds)

    def _exchange(self, exchange: Exchange) -> Exchange:
        protocol = self.session.protocol
        self.write(protocol.begin(exchange))
        deadline = self._deadline(exchange.timeout)
        while not exchange.complete:
            remaining = deadline.remaining()
            if remaining <= 0:
                protocol.abandon()
                if exchange.errors:  # the motor said why it did not answer
                    raise exchange.errors[0]
                raise CoolMuscleTimeout(f"{exchange.describe()} within {exchange.timeout:g} s")
            self.pump(remaining)
        return exchange

    def _listen(self, listen: Listen) -> MotorEvent | None:
        deadline = self._deadline(listen.timeout)
        seen = listen.since
        while True:
            for event in self.session.protocol.events_since(seen):
                seen = max(seen, event.seq)
                if listen.match(event):
                    return event
            remaining = deadline.remaining()
            if remaining <= 0:
                return None
            self.pump(remaining)
            self._let_others_in()

    def _pump_for(self, seconds: float, shared: bool = False) -> list[MotorEvent]:
        events: list[MotorEvent] = []
        deadline = self._deadline(seconds)
        while (remaining := deadline.remaining()) > 0:
            events += self.pump(remaining)
            if shared:
                self._let_others_in()
        return events

    def _let_others_in(self) -> None:
        """Between the read slices of a wait (no exchange of this thread is pending),
        another thread's operation may run: an emergency stop must not queue behind
        a ``wait_in_position`` (docs/user-guide.md, ``connect()``).  Only when another
        thread waits for its turn: a lone wait (a long one on a fast port) reads on."""
        if not self._contenders:
            return
        try:
            self.lock.release()
        except RuntimeError:                # not held (a direct call): nothing to share
            return
        try:
            time.sleep(0.001)               # a thread waiting for the lock gets it now
        finally:
            self.lock.acquire()

    # -- bytes ------------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        if not data:
            return
        try:
            self.port.write(data)
        except (SerialException, OSError) as exc:
            raise TransportError(f"cannot write to the port: {exc}") from exc

    def pump(self, wait: float) -> list[MotorEvent]:
        """Read for up to ``wait`` s (returns at the first bytes); deliver events."""
        data = self._read(wait)
        if not data:
            return []
        events = self.session.protocol.receive(data)
        for event in events:
            self.deliver(event)
        return events

    def _set_timeout(self, seconds: float) -> None:
        if self.port.timeout != seconds:
            self.port.timeout = seconds

    def _read(self, wait: float) -> bytes:
        try:
            self._set_timeout(max(0.0, min(wait, READ_SLICE)))
            data: bytes = self.port.read(1)
            if not data:
                return b""
            if self._drain_by_timeout:  # socket:// in_waiting only says 0 or 1
                self._set_timeout(0)
                rest: bytes = self.port.read(65536)
                return data + rest
            waiting = self.port.in_waiting
            return data + self.port.read(waiting) if waiting else data
        except (SerialException, OSError) as exc:
            raise TransportError(f"cannot read from the port: {exc}") from exc

    # -- events -----------------------------------------------------------------------
    def deliver(self, event: MotorEvent) -> None:
        if event.kind == "garbled":
            log.warning("unreadable line from the motor: %r", event.text)
        for listener, accepts in list(self.listeners):
            if accepts(event):
                try:
                    listener(event)
                except Exception:  # a subscriber's bug must not break the connection
                    log.exception("event listener failed")

    def subscribe(self, listener: Listener,
                  accepts: Callable[[MotorEvent], bool]) -> Callable[[], None]:
        entry = (listener, accepts)
        self.listeners.append(entry)

        def remove() -> None:
            if entry in self.listeners:
                self.listeners.remove(entry)
        return remove
