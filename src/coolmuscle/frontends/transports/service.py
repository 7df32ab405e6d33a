"""Running a chain behind transports: the simulator service and its threaded wrapper.

Owns the life cycle that ``coolmuscle sim`` uses: one asyncio loop holds the
real-time driver (:class:`coolmuscle.sim.realtime.RealtimeDriver`), the host-line
:class:`~coolmuscle.frontends.transports.base.Port` and every transport.  All model calls
happen in that loop's thread.

:class:`ServiceThread` runs the same service in a background thread, for tests,
benchmarks and programs that embed a virtual motor next to their own code.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from ...device.api import Device
from ...sim.realtime import BehindCallback, RealtimeDriver
from .base import Port, Transport

log = logging.getLogger(__name__)

T = TypeVar("T")


class Service:
    """A chain served over transports, paced to the wall clock."""

    def __init__(self, chain: Device, transports: Sequence[Transport], *, scale: float = 1.0,
                 on_behind: BehindCallback | None = None) -> None:
        self.chain = chain
        self.transports = list(transports)
        self.driver = RealtimeDriver(chain.kernel, scale=scale, on_behind=on_behind)
        self.port = Port(chain, self.driver)
        self._driver_task: asyncio.Task[None] | None = None
        self._started: list[Transport] = []

    async def start(self) -> None:
        """Start the driver and every transport; on failure nothing is left running."""
        self._driver_task = asyncio.create_task(self.driver.run(), name="coolmuscle-driver")
        try:
            for transport in self.transports:
                self._started.append(transport)   # closed too if its start is cut short
                await transport.start(self.port)
        except BaseException:
            await self.close()
            raise

    async def wait(self, stop: asyncio.Event | None = None) -> None:
        """Return when ``stop`` is set or a transport that ends the service finished."""
        waits: list[asyncio.Future[Any]] = [asyncio.ensure_future(t.finished.wait())
                                            for t in self._started if t.stops_service]
        if stop is not None:
            waits.append(asyncio.ensure_future(stop.wait()))
        if self._driver_task is not None:
            waits.append(self._driver_task)
        if not waits:
            return
        try:
            await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for fut in waits:
                if fut is not self._driver_task:
                    fut.cancel()

    async def close(self) -> None:
        """Close every started transport and stop the driver (the chain stays open)."""
        for transport in reversed(self._started):
            try:
                await transport.close()
            except Exception:  # closing must go on for the others, but never silently
                log.exception("%s: closing failed", transport.name)
        self._started.clear()
        self.driver.stop()
        if self._driver_task is not None:
            try:
                await self._driver_task
            except asyncio.CancelledError:
                pass
            self._driver_task = None

    def call(self, fn: Callable[..., T], *args: Any) -> T:
        """Run ``fn(*args)`` at the current virtual instant (loop thread only)."""
        return self.driver.call(fn, *args)


class ServiceThread:
    """Run a :class:`Service` in a background thread with its own event loop.

    ``chain_factory`` and ``transports_factory`` are called in that thread, so a
    chain that opens thread-bound resources (SQLite) is created where it is used::

        with ServiceThread(lambda: Chain(), lambda: [TcpTransport(port=0)]) as st:
            port = st.transports[0].info()["port"]
    """

    def __init__(self, chain_factory: Callable[[], Device],
                 transports_factory: Callable[[], Sequence[Transport]], *,
                 scale: float = 1.0, close_chain: bool = True) -> None:
        self._chain_factory = chain_factory
        self._transports_factory = transports_factory
        self._scale = scale
        self._close_chain = close_chain
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.service: Service | None = None

    @property
    def chain(self) -> Device:
        assert self.service is not None, "service not started"
        return self.service.chain

    @property
    def transports(self) -> list[Transport]:
        assert self.service is not None, "service not started"
        return self.service.transports

    def start(self, timeout: float = 10.0) -> ServiceThread:
        """Start the thread and wait until every transport is up (re-raises failures)."""
        self._thread = threading.Thread(target=self._main, name="coolmuscle-service", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise TimeoutError("coolmuscle service did not start in time")
        if self._error is not None:
            self._thread.join(timeout)
            raise self._error
        return self

    def _main(self) -> None:
        asyncio.run(self._amain())

    async def _amain(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        chain: Device | None = None
        try:
            chain = self._chain_factory()
            self.service = Service(chain, self._transports_factory(), scale=self._scale)
            await self.service.start()
        except BaseException as exc:  # reported to start()
            self._error = exc
            if chain is not None and self._close_chain:
                chain.close()
            self._ready.set()
            return
        self._ready.set()
        try:
            await self.service.wait(self._stop)
        finally:
            await self.service.close()
            if self._close_chain:
                chain.close()

    def call(self, fn: Callable[..., T], *args: Any, timeout: float = 10.0) -> T:
        """Run ``fn(*args)`` in the service thread at the current virtual instant."""
        assert self._loop is not None and self.service is not None, "service not started"
        service = self.service

        async def run() -> T:
            return service.call(fn, *args)
        future: concurrent.futures.Future[T] = asyncio.run_coroutine_threadsafe(run(), self._loop)
        return future.result(timeout)

    def stop(self, timeout: float = 10.0) -> None:
        """Stop the service and join the thread (idempotent)."""
        if self._thread is None:
            return
        if self._loop is not None and self._stop is not None and not self._loop.is_closed():
            try:
                self._loop.call_soon_threadsafe(self._stop.set)
            except RuntimeError:
                pass
        self._thread.join(timeout)
        self._thread = None

    def __enter__(self) -> ServiceThread:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
