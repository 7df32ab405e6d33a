"""Tests of sim/realtime.py: wall-clock mapping, catch-up, sleeping, lag, fast mode."""

from __future__ import annotations

import asyncio
import time

import pytest

from coolmuscle.device.hostline import byte_time_ns
from coolmuscle.sim.kernel import NS_PER_MS, NS_PER_S, Kernel, ms, seconds
from coolmuscle.sim.realtime import (
    FastClock,
    PreciseWaker,
    RealtimeClock,
    RealtimeDriver,
    make_clock,
)
from fakes import FakeChain


class ManualClock:
    """A wall clock the test moves by hand."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_catch_up_runs_due_events_and_leaves_now_at_wall_time() -> None:
    kernel, wall = Kernel(), ManualClock()
    fired: list[int] = []
    kernel.schedule(NS_PER_S, lambda: fired.append(kernel.now))
    clock = RealtimeClock(kernel, clock=wall)
    wall.t += 0.5
    assert clock.catch_up() == 0
    assert kernel.now == NS_PER_S // 2 and fired == []
    wall.t += 0.5
    assert clock.catch_up() == 1
    assert fired == [NS_PER_S] and kernel.now == NS_PER_S


def test_scale_maps_wall_seconds_to_more_virtual_seconds() -> None:
    kernel, wall = Kernel(), ManualClock()
    kernel.schedule(NS_PER_S, lambda: None)
    clock = RealtimeClock(kernel, scale=2.0, clock=wall)
    assert clock.seconds_until_next() == pytest.approx(0.5)
    wall.t += 0.25
    clock.catch_up()
    assert kernel.now == NS_PER_S // 2
    assert clock.seconds_until_next() == pytest.approx(0.25)


def test_seconds_until_next_is_none_when_idle_and_zero_when_overdue() -> None:
    kernel, wall = Kernel(), ManualClock()
    clock = RealtimeClock(kernel, clock=wall)
    assert clock.seconds_until_next() is None
    kernel.schedule(ms(10), lambda: None)
    wall.t += 1.0
    assert clock.seconds_until_next() == 0.0


def test_lateness_is_reported_when_an_event_runs_late() -> None:
    kernel, wall = Kernel(), ManualClock()
    lags: list[float] = []
    clock = RealtimeClock(kernel, clock=wall, behind_threshold=0.05, on_behind=lags.append)
    kernel.schedule(ms(100), lambda: None)
    wall.t += 0.101   # on time (1 ms late): not behind
    clock.catch_up()
    assert lags == [] and clock.late_count == 0
    kernel.schedule(ms(100), lambda: None)
    wall.t += 0.3     # 200 ms late
    clock.catch_up()
    assert lags == [pytest.approx(0.2)]
    assert clock.late_count == 1 and clock.max_lag == pytest.approx(0.2)


def test_clock_reanchors_when_the_kernel_was_advanced_by_someone_else() -> None:
    kernel, wall = Kernel(), ManualClock()
    clock = RealtimeClock(kernel, clock=wall)
    kernel.advance(seconds(5))
    wall.t += 0.1
    clock.catch_up()
    assert kernel.now == seconds(5)        # never backwards
    wall.t += 0.1
    clock.catch_up()
    assert kernel.now == seconds(5.1)


def test_bad_scale_is_refused() -> None:
    for bad in (0.0, -1.0, float("inf"), float("nan")):
        with pytest.raises(ValueError):
            RealtimeClock(Kernel(), scale=bad)


def test_fast_clock_moves_only_when_advanced() -> None:
    kernel = Kernel()
    clock = FastClock(kernel)
    hits: list[int] = []
    kernel.schedule(seconds(2), lambda: hits.append(kernel.now))
    assert clock.catch_up() == 0 and clock.seconds_until_next() is None
    assert kernel.now == 0
    assert clock.run_until(lambda: bool(hits), seconds(5))
    assert kernel.now == seconds(2)
    clock.advance(seconds(1))
    assert kernel.now == seconds(3)


def test_make_clock_modes() -> None:
    assert isinstance(make_clock(Kernel(), "fast"), FastClock)
    assert isinstance(make_clock(Kernel(), "realtime", scale=3), RealtimeClock)
    with pytest.raises(ValueError):
        make_clock(Kernel(), "slow")


def _run(coro) -> object:
    return asyncio.run(asyncio.wait_for(coro, 10))


def test_driver_runs_an_event_at_its_wall_time() -> None:
    async def main() -> float:
        kernel = Kernel()
        driver = RealtimeDriver(kernel)
        start = time.monotonic()
        fired: list[float] = []
        kernel.schedule(ms(80), lambda: (fired.append(time.monotonic() - start), driver.stop()))
        await driver.run()
        return fired[0]
    elapsed = _run(main())
    assert 0.075 <= elapsed < 0.3


def test_driver_is_woken_by_input_that_schedules_an_earlier_event() -> None:
    async def main() -> tuple[float, int]:
        kernel = Kernel()
        driver = RealtimeDriver(kernel)
        kernel.schedule(seconds(30), lambda: None)   # far away: the driver sleeps long
        task = asyncio.create_task(driver.run())
        await asyncio.sleep(0.02)
        start = time.monotonic()
        fired: list[float] = []
        at_input = driver.call(lambda: kernel.now)
        driver.call(kernel.schedule, ms(50), lambda: fired.append(time.monotonic() - start))
        while not fired:
            await asyncio.sleep(0.005)
        driver.stop()
        await task
        return fired[0], at_input
    elapsed, at_input = _run(main())
    assert 0.045 <= elapsed < 0.3
    assert at_input >= ms(15)   # input arrived at the virtual instant matching the wall clock


def test_driver_reports_falling_behind() -> None:
    async def main() -> list[float]:
        kernel = Kernel()
        lags: list[float] = []
        driver = RealtimeDriver(kernel, on_behind=lags.append)
        kernel.schedule(ms(10), lambda: None)
        kernel.schedule(ms(20), driver.stop)
        task = asyncio.create_task(driver.run())
        await asyncio.sleep(0.001)   # the driver anchors and goes to sleep
        time.sleep(0.2)   # block the loop: the events become overdue
        await task
        return lags
    lags = _run(main())
    assert lags and lags[0] >= 0.15


def test_driver_with_wire_pacing_keeps_exact_virtual_byte_times() -> None:
    async def main() -> tuple[int, list[tuple[int, bytes]]]:
        chain = FakeChain(pacing=True)
        driver = RealtimeDriver(chain.kernel)
        got: list[tuple[int, bytes]] = []
        chain.host_line.add_listener(lambda data: got.append((chain.kernel.now, data)))
        task = asyncio.create_task(driver.run())
        await asyncio.sleep(0.01)
        t0 = driver.call(lambda: (chain.kernel.now, chain.host_line.feed(b"?96.1\r"))[0])
        while len(got) < 2:
            await asyncio.sleep(0.001)
        driver.stop()
        await task
        return t0, got
    t0, got = _run(main())
    bt = byte_time_ns(38400)
    assert got == [(t0 + 13 * bt, b"?96.1\r\n"), (t0 + 21 * bt, b"Px.1=1\r\n")]
    assert 21 * bt < 6 * NS_PER_MS


def test_a_failing_event_is_logged_and_later_events_still_run() -> None:
    kernel, wall = Kernel(), ManualClock()
    ran: list[str] = []

    def fail() -> None:
        raise RuntimeError("model bug")
    kernel.schedule(ms(1), fail)
    kernel.schedule(ms(2), lambda: ran.append("after"))
    clock = RealtimeClock(kernel, clock=wall)
    wall.t += 0.01
    clock.catch_up()
    assert ran == ["after"] and clock.errors == 1 and kernel.now == ms(10)


def test_the_precise_waker_calls_back_in_the_loop_once_per_arming() -> None:
    """PreciseWaker: the callback runs in the loop's thread, at or after the deadline;
    a disarmed or replaced deadline does not fire; close ends the thread."""
    import threading

    async def main() -> tuple[list[tuple[float, bool]], int]:
        loop = asyncio.get_running_loop()
        got: list[tuple[float, bool]] = []
        loop_thread = threading.current_thread()
        waker = PreciseWaker(loop, lambda: got.append(
            (time.monotonic(), threading.current_thread() is loop_thread)))
        try:
            deadline = time.monotonic() + 0.003
            waker.arm(deadline)
            await asyncio.sleep(0.05)
            waker.arm(time.monotonic() + 0.02)       # disarmed before it is due
            waker.disarm()
            waker.arm(time.monotonic() + 1.0)        # replaced by an earlier one
            second = time.monotonic() + 0.002
            waker.arm(second)
            await asyncio.sleep(0.05)
            assert [t >= d for (t, _), d in zip(got, (deadline, second))] == [True, True]
        finally:
            waker.close()
        assert not waker._thread.is_alive()
        return got, waker.wakes
    got, wakes = _run(main())
    assert len(got) == 2 == wakes and all(in_loop for _, in_loop in got)


def test_a_precise_driver_runs_short_waits_through_the_waker() -> None:
    """``RealtimeDriver.precise`` (the EtherCAT transport sets it): events closer than
    PRECISE_BELOW are woken for by the waker, on time, and the waker ends with the run."""
    async def main() -> tuple[list[float], RealtimeDriver]:
        kernel = Kernel()
        driver = RealtimeDriver(kernel)
        driver.precise = True
        start = time.monotonic()
        fired: list[float] = []

        def tick() -> None:
            fired.append(time.monotonic() - start)
            if len(fired) < 20:
                kernel.schedule(ms(1), tick)
            else:
                driver.stop()
        kernel.schedule(ms(1), tick)
        await driver.run()
        return fired, driver
    fired, driver = _run(main())
    assert len(fired) == 20 and fired[-1] >= 0.0199
    assert driver.waker is not None and driver.waker.wakes >= 10
    assert not driver.waker._thread.is_alive()
