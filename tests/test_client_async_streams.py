"""The asyncio client's waits and event streams (docs/host-library.md "asyncio"):
virtual time on ``coolmuscle://?mode=fast`` moves while the client waits and only as far
as it waits, as with the sync client; ``events()`` ends when the connection closes or
fails instead of waiting for ever."""

from __future__ import annotations

import asyncio
import socket
import threading
from typing import Any

import pytest

from coolmuscle import connect, connect_async
from coolmuscle.client import MotorEvent
from coolmuscle.errors import CoolMuscleTimeout, TransportError
from coolmuscle.sim.kernel import NS_PER_S


def run(coro: Any) -> Any:
    return asyncio.run(asyncio.wait_for(coro, 30))


def test_fast_mode_moves_and_reports_in_position_as_the_guide_shows() -> None:
    """The guide's asyncio example on the in-process motor: 2.1 "Ux.1=8" at the end
    (the position read at the in-position instant is within K55 of the target: ch. 3
    K55, docs/fidelity.md "In position")."""
    async def session() -> tuple[str, float]:
        async with await connect_async("coolmuscle://?mode=fast") as m:
            await m.move_to(10000, speed=100, accel=100)
            await m.wait_in_position(timeout=5)
            assert await m.get_position() == 9995
            stream = m.events(kinds=["status"])
            await m.move_to(0, speed=100, accel=100)
            event = await stream.__anext__()
            await stream.aclose()
            return event.text, m.port.kernel.now / NS_PER_S
    text, virtual = run(session())
    assert text == "Ux.1=8"
    assert 2.0 < virtual < 10.0          # two 1.1 s moves, not a runaway clock


def _sync_move() -> tuple[int, int]:
    with connect("coolmuscle://?mode=fast") as m:
        m.move_to(10000, speed=100, accel=100)
        m.wait_in_position(timeout=5)
        return m.get_position(), m.port.kernel.now


async def _async_move() -> tuple[int, int]:
    async with await connect_async("coolmuscle://?mode=fast") as m:
        await m.move_to(10000, speed=100, accel=100)
        await m.wait_in_position(timeout=5)
        return await m.get_position(), m.port.kernel.now


def test_fast_mode_runs_are_deterministic_and_the_same_as_the_sync_client() -> None:
    """docs/transports.md "mode=fast": the same calls give the same bytes at the same
    virtual times.  The asyncio client's waits move virtual time themselves, one read
    at a time, so nothing moves it while the loop has not yet seen a reply (a reader
    thread that ran time on its own put the motor in position at 3, 4 or 5 s)."""
    expected = _sync_move()
    assert expected == (9995, 1_093_905_243)        # K55: in position 5 pulses short
    outcomes = {asyncio.run(asyncio.wait_for(_async_move(), 10)) for _ in range(150)}
    assert outcomes == {expected}


def test_fast_mode_time_stands_still_between_requests() -> None:
    async def session() -> tuple[float, float]:
        async with await connect_async("coolmuscle://?mode=fast") as m:
            await m.get_position()
            before = m.port.kernel.now
            await asyncio.sleep(0.3)          # the client waits for nothing of the motor
            return before, m.port.kernel.now
    before, after = run(session())
    assert after == before


def test_fast_mode_delivers_what_a_line_produced_at_once_without_a_wait() -> None:
    """A line written with no request waiting (a terminal's): its reply, said at this
    very instant, reaches the subscribers; virtual time stands still."""
    async def session() -> tuple[list[str], int]:
        async with await connect_async("coolmuscle://?mode=fast") as m:
            seen: list[str] = []
            m.subscribe(lambda e: seen.append(e.text))
            m.write_line("?96.1")
            for _ in range(100):
                if seen:
                    break
                await asyncio.sleep(0.01)
            return seen, m.port.kernel.now
    seen, now = run(session())
    assert seen == ["Px.1=0"] and now == 0


def test_fast_mode_wait_event_times_out_in_virtual_time() -> None:
    async def session() -> float:
        async with await connect_async("coolmuscle://?mode=fast") as m:
            start = m.port.kernel.now
            with pytest.raises(CoolMuscleTimeout):
                await m.wait_event(kind="status", timeout=2.0)
            return (m.port.kernel.now - start) / NS_PER_S
    waited = run(session())
    assert 1.9 <= waited <= 2.1


def test_events_end_when_the_connection_closes() -> None:
    async def session() -> list[MotorEvent]:
        m = await connect_async("coolmuscle://?scale=4")
        got: list[MotorEvent] = []

        async def consume() -> str:
            async for event in m.events():
                got.append(event)
            return "ended"
        task = asyncio.create_task(consume())
        await m.move_to(100, speed=100, accel=100)
        await m.wait_in_position(timeout=5)
        await asyncio.sleep(0.1)
        await m.close()
        assert await asyncio.wait_for(task, 3) == "ended"
        return got
    got = run(session())                  # (the consumer ended: asserted inside)
    assert all(isinstance(e, MotorEvent) for e in got)


def test_events_end_with_the_transport_error_when_the_peer_goes() -> None:
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]

    def peer() -> None:
        conn, _ = server.accept()
        conn.recv(100)
        conn.close()                      # the motor's line is gone
    thread = threading.Thread(target=peer, daemon=True)
    thread.start()

    async def session() -> BaseException | None:
        m = await connect_async(f"socket://127.0.0.1:{port}", timeout=0.5, firmware="cm2")
        stream = m.events()
        with pytest.raises((TransportError, CoolMuscleTimeout)):
            await m.get_position()
        try:
            await asyncio.wait_for(stream.__anext__(), 3)
        except TransportError as exc:
            return exc
        finally:
            await m.close()
        return None
    try:
        assert isinstance(run(session()), TransportError)
    finally:
        thread.join(2)
        server.close()


def test_fast_mode_a_wait_pending_at_close_ends_with_the_transport_error() -> None:
    async def session() -> BaseException | None:
        m = await connect_async("coolmuscle://?mode=fast")

        async def wait() -> BaseException | None:
            try:
                await m.wait_event(kind="input", timeout=100000)
            except (TransportError, CoolMuscleTimeout) as exc:
                return exc
            return None
        task = asyncio.create_task(wait())
        await asyncio.sleep(0.3)
        await m.close()
        return await asyncio.wait_for(task, 5)
    assert isinstance(run(session()), TransportError)
