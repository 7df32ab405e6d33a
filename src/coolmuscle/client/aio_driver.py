"""The asyncio driver: runs sans-IO operations as coroutines over any pyserial port.

The twin of :mod:`coolmuscle.client.driver`.  A helper thread does the blocking reads
(pyserial has no asyncio interface) and hands the bytes to the event loop, where they
feed the shared :class:`~coolmuscle.client.protocol.Protocol`; events reach subscribers
as they arrive.  Requests wait on a condition the reader notifies; every wait has its
timeout (wall clock, the loop's time).  On a fast in-process port
(``coolmuscle://?mode=fast``) the waits themselves move virtual time, one read at a
time, so that runs are deterministic (:class:`_ThreadedReader`).
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
from collections.abc import Callable
from typing import Any

import serial

from ..errors import CoolMuscleError, CoolMuscleTimeout, TransportError
from . import ops
from .driver import READ_SLICE, Listener, _Deadline, port_clock
from .protocol import Exchange, MotorEvent

log = logging.getLogger(__name__)

__all__ = ["AsyncDriver"]


class _ThreadedReader:
    """Blocking reads in a thread; bytes are handed to ``on_data`` in the loop.

    A port whose virtual time moves inside ``read`` (``coolmuscle://?mode=fast``) has no
    reading thread of its own: time moves only in :meth:`step`, one read at a time,
    which the waits of the loop take in turn (:meth:`AsyncDriver._until`), each as far
    as the nearest end of a waiting request (``horizons``, virtual seconds) and no
    further than the first bytes.  So the loop sees every byte before time moves on,
    and a run gives the same bytes at the same virtual instants every time, as the
    sync driver does (docs/transports.md "mode=fast")."""

    def __init__(self, port: Any, loop: asyncio.AbstractEventLoop,
                 on_data: Callable[[bytes | BaseException], None]) -> None:
        self._port = port
        self._loop = loop
        self._on_data = on_data
        self._stop = threading.Event()
        self._socket = type(port).__module__.endswith("protocol_socket")
        self.clock, self.fast = port_clock(port)    # virtual seconds on a fast port
        #: ends (virtual s) of the requests waiting now; fast ports only
        self.horizons: list[float] = []
        #: a fast port: one read at a time moves its time (:meth:`step`)
        self.steps = asyncio.Lock()
        self._thread = threading.Thread(target=self._main, name="coolmuscle-reader",
                                        daemon=True)

    def start(self) -> None:
        if self.fast:
            return
        self._port.timeout = 0.05
        self._thread.start()

    def fast_timeout(self) -> float:
        """How far the next read of a fast port may move virtual time: up to the
        nearest end of a waiting request, at most a read slice."""
        horizon = min(self.horizons, default=None)
        if horizon is None:
            return 0.0
        return max(0.0, min(READ_SLICE, horizon - self.clock()))

    async def step(self, timeout: float | None = None) -> None:
        """One read of a fast port (in a worker thread: the loop stays free while the
        chain runs), its bytes (or its failure) handed over before it returns.
        ``timeout``: how far it may move virtual time (default :meth:`fast_timeout`)."""
        wait = self.fast_timeout() if timeout is None else timeout
        data = await self._loop.run_in_executor(None, self._read_fast, wait)
        if not self._stop.is_set():
            self._on_data(data)

    async def drain(self) -> None:
        """What a fast port holds now, with virtual time standing still (the replies
        a write produced at once): delivered to subscribers without a wait."""
        async with self.steps:
            if not self._stop.is_set():
                await self.step(0.0)

    def _read_fast(self, timeout: float) -> bytes | BaseException:
        try:
            self._port.timeout = timeout
            data: bytes = self._port.read(1)
            if data:
                self._port.timeout = 0
                data += self._port.read(65536)
            return data
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            return exc

    def _main(self) -> None:
        while not self._stop.is_set():
            try:
                data = self._port.read(1)
                if data and self._socket:  # socket:// in_waiting only says 0 or 1
                    self._port.timeout = 0
                    data += self._port.read(65536)
                    self._port.timeout = 0.05
                elif data and self._port.in_waiting:
                    data += self._port.read(self._port.in_waiting)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                if not self._stop.is_set():
                    self._loop.call_soon_threadsafe(self._on_data, exc)
                return
            if data and not self._stop.is_set():
                try:
                    self._loop.call_soon_threadsafe(self._on_data, data)
                except RuntimeError:  # the loop is closed
                    return

    def stop(self) -> None:
        self._stop.set()
        cancel = getattr(self._port, "cancel_read", None)
        if cancel is not None:
            try:
                cancel()
            except (serial.SerialException, OSError):
                pass
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(1.0)


class AsyncDriver:
    """Runs operations as coroutines; a reader feeds the shared protocol core."""

    def __init__(self, port: Any, session: ops.Session) -> None:
        self.port = port
        self.session = session
        self.listeners: list[tuple[Listener, Callable[[MotorEvent], bool]]] = []
        #: ``tap(direction, data)`` sees every byte written (``">"``) and read (``"<"``).
        self.taps: list[Callable[[str, bytes], None]] = []
        self.lock = asyncio.Lock()
        self._changed = asyncio.Condition()
        self._failure: BaseException | None = None
        self._loop = asyncio.get_running_loop()
        self._reader = _ThreadedReader(port, self._loop, self._received)
        #: fast port: the reads of what a write produced at once (kept till done)
        self._drains: set[asyncio.Task[None]] = set()
        #: called once when the port fails (the event streams end with the error)
        self.on_failure: list[Callable[[BaseException], None]] = []

    def start(self) -> None:
        self._reader.start()

    def close(self) -> None:
        self._reader.stop()

    def now(self) -> float:
        """The clock of timeouts: the loop's, or virtual time on a fast port."""
        return self._reader.clock() if self._reader.fast else self._loop.time()

    @property
    def failure(self) -> BaseException | None:
        """Why the port stopped working (``None``: it works)."""
        return self._failure

    def waiting(self, seconds: float) -> _Waiting:
        """While inside, a fast port's virtual time may move ``seconds`` on."""
        return _Waiting(self._reader, seconds)

    async def advance_until(self, ready: Callable[[], bool]) -> None:
        """On a fast port, move virtual time until ``ready()`` (an event stream waiting
        for its next event), for as long as it takes; elsewhere time moves by itself
        and this returns at once."""
        if self._reader.fast:
            await self._until_fast(ready, math.inf)

    def _received(self, data: bytes | BaseException) -> None:
        if isinstance(data, BaseException):
            first = self._failure is None
            self._failure = TransportError(f"cannot read from the port: {data}")
            if first:
                for callback in list(self.on_failure):
                    callback(self._failure)
        elif data:
            self._tap("<", data)
            for event in self.session.protocol.receive(data):
                self._deliver(event)
        self._loop.create_task(self._notify())

    async def _notify(self) -> None:
        async with self._changed:
            self._changed.notify_all()

    def _deliver(self, event: MotorEvent) -> None:
        if event.kind == "garbled":
            log.warning("unreadable line from the motor: %r", event.text)
        for listener, accepts in list(self.listeners):
            if accepts(event):
                try:
                    listener(event)
                except Exception:
                    log.exception("event listener failed")

    async def _until(self, ready: Callable[[], bool], seconds: float) -> bool:
        if self._reader.fast:
            return await self._until_fast(ready, seconds)
        deadline = _Deadline(self.now, False, seconds)
        async with self._changed:
            while not ready():
                if self._failure is not None:
                    raise self._failure
                remaining = deadline.remaining()
                if remaining <= 0:
                    return False
                # asyncio.timeout, not wait_for: on Python 3.11 wait_for swallows a
                # cancellation that comes as the condition is notified, and a cancelled
                # poll went on polling (a page that never stopped on Ctrl-C).
                try:
                    async with asyncio.timeout(remaining):
                        await self._changed.wait()
                except TimeoutError:
                    pass
        return True

    async def _until_fast(self, ready: Callable[[], bool], seconds: float) -> bool:
        """A wait on a fast port: it moves virtual time itself, a read at a time, taking
        turns with the other waits (each looks at what the last read brought before
        the next moves time on).  The sync driver's deadline: virtual, with the wall
        clock as a backstop (a port closed meanwhile stops its time for good)."""
        deadline = _Deadline(self.now, True, seconds)
        reader = self._reader
        with self.waiting(seconds):
            while not ready():
                async with reader.steps:
                    if ready():
                        break
                    if self._failure is not None:
                        raise self._failure
                    if deadline.remaining() <= 0:
                        return False
                    if getattr(self.port, "kernel", None) is None:
                        raise TransportError("the port was closed during the wait")
                    await reader.step()
        return True

    async def run(self, op: ops.Op[ops.T]) -> ops.T:
        async with self.lock:
            result: Any = None
            error: BaseException | None = None
            while True:
                try:
                    request = op.throw(error) if error is not None else op.send(result)
                except StopIteration as stop:
                    return stop.value  # type: ignore[no-any-return]
                result, error = None, None
                try:
                    result = await self._do(request)
                except CoolMuscleError as exc:
                    error = exc

    async def _do(self, request: Any) -> Any:
        protocol = self.session.protocol
        if isinstance(request, ops.Now):
            return self.now()
        if isinstance(request, ops.Pause):
            await self._until(lambda: False, request.seconds)
            return None
        if isinstance(request, ops.Listen):
            found: list[MotorEvent] = []

            def matched() -> bool:
                found[:] = [e for e in protocol.events_since(request.since)
                            if request.match(e)][:1]
                return bool(found)
            await self._until(matched, request.timeout)
            return found[0] if found else None
        if isinstance(request, Exchange):
            self.write(protocol.begin(request))
            if not await self._until(lambda: request.complete, request.timeout):
                protocol.abandon()
                if request.errors:  # the motor said why it did not answer
                    raise request.errors[0]
                raise CoolMuscleTimeout(f"{request.describe()} within {request.timeout:g} s")
            return request
        raise TypeError(f"unknown request {request!r}")

    def _tap(self, direction: str, data: bytes) -> None:
        for tap in list(self.taps):
            try:
                tap(direction, data)
            except Exception:
                log.exception("byte tap failed")

    def write(self, data: bytes) -> None:
        if not data:
            return
        if self._failure is not None:      # the port is gone: nothing written is lost silently
            raise self._failure
        self._tap(">", data)
        try:
            self.port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"cannot write to the port: {exc}") from exc
        if self._reader.fast:              # its replies at this instant, waited for or not
            task = self._loop.create_task(self._reader.drain())
            self._drains.add(task)
            task.add_done_callback(self._drains.discard)


class _Waiting:
    """A request waiting: its end is a horizon of a fast port's reader."""

    def __init__(self, reader: _ThreadedReader, seconds: float) -> None:
        self._reader = reader
        self._end = reader.clock() + seconds if reader.fast else 0.0

    def __enter__(self) -> _Waiting:
        if self._reader.fast:
            self._reader.horizons.append(self._end)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._reader.fast:
            self._reader.horizons.remove(self._end)
