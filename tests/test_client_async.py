"""The asyncio twin: same operations, same core, on the three targets; same API."""

from __future__ import annotations

import asyncio
import inspect
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import serial

from client_targets import TARGETS, Target, target_fixture
from coolmuscle import connect_async
from coolmuscle.client import AsyncCoolMuscle, AsyncMotor, CoolMuscle, Motor, MotorEvent
from coolmuscle.client.aio_driver import AsyncDriver
from coolmuscle.client.ops import Op, Pause, Session
from coolmuscle.errors import AlarmError, CmlSyntaxError, CoolMuscleTimeout, OutOfRangeError


@pytest.fixture(params=TARGETS)
def target(request: Any, tmp_path: Path) -> Iterator[Target]:
    yield from target_fixture(request.param, tmp_path, motors=2)


def run(coro: Any) -> Any:
    return asyncio.run(asyncio.wait_for(coro, 30))


def url_of(target: Target) -> str:
    # in-process: a realtime chain (fast mode would let a reader thread run time freely)
    return "coolmuscle://?motors=2&scale=4" if target.name == "inproc" else target.url


def test_async_operations_on_each_target(target: Target) -> None:
    async def session() -> dict[str, Any]:
        async with await connect_async(url_of(target)) as m:
            events: list[MotorEvent] = []
            m.subscribe(events.append, kinds=["status"])
            record = {"position": await m.get_position(), "status": int(await m.get_status()),
                      "version": (await m.get_version()).series}
            await m.write_param(44, 120)
            record["k44"] = await m.read_param(44)
            with pytest.raises(OutOfRangeError):
                await m.write_register("M", 1, 500)
            await m.move_to(1500, speed=300, accel=1000)
            record["arrived"] = int(await m.wait_in_position(timeout=5))
            await asyncio.sleep(0.1)
            record["at"] = await m.get_position()
            record["motor2"] = await m.motor(2).get_position()
            await m.write_param(23, 17)
            with pytest.raises(CmlSyntaxError):
                await m.send("hello")
            with pytest.raises(CoolMuscleTimeout):
                await m.motor(3).get_position()
            record["events"] = [e.text for e in events]
            return record
    assert run(session()) == {"position": 0, "status": 8, "version": "CM2", "k44": 120,
                              "arrived": 8, "at": 1500, "motor2": 0,
                              "events": ["Ux.1=8"]}


def test_events_arrive_between_calls_and_alarms_raise(target: Target) -> None:
    async def session() -> None:
        async with await connect_async(url_of(target)) as m:
            await m.move_to(100000, speed=20, accel=100)
            stream = m.events(kinds=["status"])
            raise_alarm(target, m, 2)
            event = await asyncio.wait_for(stream.__anext__(), 3)   # no call in between
            await stream.aclose()
            assert (event.kind, event.value) == ("status", 2)
            with pytest.raises(AlarmError) as caught:
                await m.wait_in_position(timeout=3)
            assert caught.value.status == 2
    run(session())


def raise_alarm(target: Target, m: AsyncCoolMuscle, bits: int) -> None:
    """An alarm now, in the model's thread (the in-process port's lock for coolmuscle://)."""
    if target.name == "inproc":
        with m.port._cond:
            m.port.chain.motors[1].raise_alarm(bits)
    else:
        target.inject(lambda chain: chain.motors[1].raise_alarm(bits))


def test_the_async_api_mirrors_the_sync_api() -> None:
    def public(cls: type) -> set[str]:
        return {name for name, value in vars(cls).items()
                if not name.startswith("_") and callable(value)}
    sync_methods = public(Motor) | public(CoolMuscle)
    async_methods = public(AsyncMotor) | public(AsyncCoolMuscle)
    assert sync_methods - {"poll"} <= async_methods | {"poll"}
    for name in public(Motor):
        assert inspect.iscoroutinefunction(getattr(AsyncMotor, name)), name


def _pause(seconds: float) -> Op[None]:
    yield Pause(seconds)


def test_a_request_cancelled_as_bytes_arrive_ends() -> None:
    """A cancelled request ends, even when the motor's bytes wake it in the same
    instant.  (asyncio.wait_for on Python 3.11 returns instead of raising there: the
    page of a real motor, whose poll is cancelled on Ctrl-C, went on polling.)"""
    async def main() -> None:
        port = serial.serial_for_url("loop://", timeout=0.05)
        driver = AsyncDriver(port, Session())
        driver.start()
        try:
            for turns in range(8):                  # each step of the wake-up in turn
                task = asyncio.create_task(driver.run(_pause(30.0)))
                await asyncio.sleep(0.01)           # the request waits for bytes
                driver._received(b"x")              # ... and they come
                for _ in range(turns):
                    await asyncio.sleep(0)
                task.cancel()
                await asyncio.wait({task}, timeout=5)
                assert task.cancelled(), f"the request went on ({turns} steps)"
        finally:
            driver.close()
            port.close()
    asyncio.run(main())
