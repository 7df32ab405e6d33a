"""The asyncio client: :func:`connect_async`, :class:`AsyncCoolMuscle`, :class:`AsyncMotor`.

The twin of :mod:`coolmuscle.client.sync`: the same operations
(:mod:`coolmuscle.client.ops`) and the same protocol core, driven by coroutines::

    async with await connect_async("socket://127.0.0.1:5150") as m:
        await m.move_to(10000, speed=100, accel=100)
        await m.wait_in_position(timeout=5)
        print(await m.get_position())

Any pyserial URL works: a helper thread does the blocking reads and hands the bytes to
the event loop (:mod:`coolmuscle.client.aio_driver`), so events reach subscribers as
they arrive, also between calls.  Timeouts are wall-clock seconds (on
``coolmuscle://?mode=fast`` virtual time then runs as fast as the reads go).
"""

from __future__ import annotations

import asyncio
import weakref
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import serial

from ..errors import CoolMuscleTimeout, InvalidArgumentError
from ..motor.status import Ux
from . import args, banks, commands, ops
from .aio_driver import AsyncDriver
from .driver import Listener
from .program import ProgramFile
from .protocol import MotorEvent
from .replies import Version, parse_version
from .sync import open_port, program_of

__all__ = ["connect_async", "AsyncCoolMuscle", "AsyncMotor", "EventStream"]


class AsyncMotor:
    """One motor ID on the chain (asyncio); obtain with :meth:`AsyncCoolMuscle.motor`."""

    def __init__(self, driver: AsyncDriver, motor_id: int) -> None:
        self._driver = driver
        self.id = args.motor_id(motor_id)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} ID{self.id}>"

    @property
    def _session(self) -> ops.Session:
        return self._driver.session

    async def _run(self, op: ops.Op[ops.T]) -> ops.T:
        return await self._driver.run(op)

    async def send(self, line: str, *, timeout: float | None = None) -> list[str]:
        """As :meth:`coolmuscle.client.Motor.send`."""
        answer = await self._run(banks.send_line(self._session, self.id, line, timeout))
        if "K" in line.upper():
            self._session.cache(self.id).params.clear()
        return answer

    async def _int(self, number: int, name: str) -> int:
        return await self._run(ops.query_int(self._session, self.id, number, name))

    async def get_position(self) -> int:
        """``?96`` Px."""
        return await self._int(96, "Px")

    async def get_speed(self) -> int:
        """``?97`` Sx."""
        return await self._int(97, "Sx")

    async def get_torque(self) -> int:
        """``?98`` Ix."""
        return await self._int(98, "Ix")

    async def get_position_error(self) -> int:
        """``?95`` Pe."""
        return await self._int(95, "Pe")

    async def get_status(self) -> Ux:
        """``?99`` Ux flags."""
        return await self._run(ops.status(self._session, self.id))

    async def get_inputs(self) -> int:
        """``?70`` input word."""
        return await self._run(ops.io_word(self._session, self.id, 70, "IN"))

    async def get_outputs(self) -> int:
        """``?50`` output word."""
        return await self._run(ops.io_word(self._session, self.id, 50, "OUT"))

    async def get_output(self, number: int) -> bool:
        """``?51``..``?54``."""
        return await self._run(commands.output(self._session, self.id, number))

    async def get_temperature(self) -> int:
        """``?71`` °C."""
        return await self._int(71, "Temp")

    async def get_voltage(self) -> float:
        """``?72`` in volts."""
        return await self._int(72, "VSEN") / 10

    async def get_analog(self) -> int:
        """``?74`` 0..1023."""
        return await self._int(74, "ADI0")

    async def get_encoder_count(self) -> int:
        """``?76`` Ecnt."""
        return await self._int(76, "Ecnt")

    async def get_version(self) -> Version:
        """``?85`` parsed."""
        return parse_version(await self._run(commands._version_line(self._session, self.id)))

    async def get_direct_data(self) -> dict[str, int]:
        """``?.n``."""
        return await self._run(ops.direct_data(self._session, self.id))

    async def read_register(self, kind: str, index: int = 0) -> int | str:
        """As :meth:`coolmuscle.client.Motor.read_register`."""
        return await self._run(commands.read_register(self._session, self.id, kind, index))

    async def write_register(self, kind: str, index: int, value: int | str) -> None:
        """As :meth:`coolmuscle.client.Motor.write_register`."""
        await self._run(commands.write_register(self._session, self.id, kind, index, value))

    async def read_param(self, k: int) -> int:
        """``K#.n``; a K number the firmware lacks is refused."""
        return await self._run(commands.read_param(self._session, self.id, k))

    async def read_params(self) -> dict[int, int]:
        """``?90``."""
        return await self._run(ops.params(self._session, self.id))

    async def write_param(self, k: int, value: int) -> None:
        """As :meth:`coolmuscle.client.Motor.write_param`."""
        await self._run(commands.write_param(self._session, self.id, k, value))

    async def move_to(self, position: int, speed: int | None = None,
                      accel: int | None = None, *, torque: int | None = None) -> Ux:
        """As :meth:`coolmuscle.client.Motor.move_to`."""
        return await self._run(commands.move(self._session, self.id, position, speed=speed,
                                             accel=accel, torque=torque))

    async def move_by(self, distance: int, speed: int | None = None,
                      accel: int | None = None, *, torque: int | None = None) -> Ux:
        """As :meth:`coolmuscle.client.Motor.move_by`."""
        return await self._run(commands.move(self._session, self.id, distance,
                                             relative=True, speed=speed, accel=accel,
                                             torque=torque))

    async def run(self, speed: int, accel: int | None = None) -> Ux:
        """Continuous rotation."""
        return await self._run(commands.run_continuous(self._session, self.id, speed, accel))

    async def _status_command(self, text: str) -> Ux:
        return await self._run(commands.motion(self._session, self.id, [text]))

    async def stop(self) -> Ux:
        """``]1.n``."""
        return await self._status_command(f"]1.{self.id}")

    async def emergency_stop(self) -> Ux:
        """``*`` (all motors)."""
        return await self._status_command("*")

    async def release_emergency_stop(self) -> Ux:
        """``*1``."""
        return await self._status_command("*1")

    async def enable(self) -> Ux:
        """``(.n``."""
        return await self._status_command(f"(.{self.id}")

    async def free(self) -> Ux:
        """``).n``."""
        return await self._status_command(f").{self.id}")

    async def origin_search(self) -> Ux:
        """``|.n``."""
        return await self._status_command(f"|.{self.id}")

    async def go_origin(self) -> Ux:
        """``|1.n``."""
        return await self._status_command(f"|1.{self.id}")

    async def set_origin(self) -> Ux:
        """``|2.n``."""
        return await self._status_command(f"|2.{self.id}")

    async def wait_in_position(self, timeout: float = ops.DEFAULT_WAIT) -> Ux:
        """As :meth:`coolmuscle.client.Motor.wait_in_position`."""
        return await self._run(ops.wait_in_position(self._session, self.id, timeout))

    async def set_output(self, number: int, on: bool = True) -> None:
        """``O#.n`` / ``F#.n``."""
        await self._run(commands.set_output(self._session, self.id, number, on))

    async def upload(self, source: str | Path | ProgramFile, *, verify: bool = True,
                     progress: banks.Progress | None = None, check: bool = True,
                     line_delay: float = banks.DEFAULT_LINE_DELAY) -> banks.UploadResult:
        """As :meth:`coolmuscle.client.Motor.upload`."""
        result = await self._run(banks.upload(self._session, program_of(source),
                                              verify=verify, line_delay=line_delay,
                                              progress=progress))
        self._session.cache(self.id).params.clear()
        if check and not result.ok:
            raise banks.UploadError(result)
        return result

    async def read_bank(self, number: int, *, ladder: bool = False) -> list[str]:
        """``?#.n`` / ``?L#.n``."""
        return await self._run(banks.read_bank(self._session, self.id, number, ladder))

    async def read_all_banks(self) -> dict[str, list[str]]:
        """``?1000.n``."""
        return await self._run(banks.all_banks(self._session, self.id))

    async def start_bank(self, number: int) -> None:
        """``[#.n``."""
        number = await self._run(commands.bank_number(self._session, self.id, number))
        await self.send(f"[{number}.{self.id}")

    async def pause_bank(self) -> None:
        """``]``."""
        await self.send("]")

    async def stop_bank(self) -> None:
        """``]`` twice."""
        await self.send("]")
        await self.send("]")

    async def start_ladder(self, number: int) -> None:
        """``[L#.n``."""
        number = await self._run(commands.bank_number(self._session, self.id, number,
                                                      ladder=True))
        await self.send(f"[L{number}.{self.id}")

    async def stop_ladder(self) -> None:
        """``]L.n``."""
        await self.send(f"]L.{self.id}")

    async def save(self, timeout: float = 5.0) -> None:
        """``$.n``; waits for ``saved.n``."""
        await self._run(banks.save(self._session, self.id, timeout))


class EventStream:
    """An async iterator over events (see :meth:`AsyncCoolMuscle.events`).

    It ends (``StopAsyncIteration``) after :meth:`aclose` or when the connection is
    closed, once the events received before are taken; a port that fails ends it with
    the :class:`~coolmuscle.errors.TransportError`."""

    def __init__(self, client: AsyncCoolMuscle, kinds: Iterable[str] | None,
                 motor: int | None) -> None:
        self._queue: asyncio.Queue[MotorEvent | BaseException | None] = asyncio.Queue()
        self._driver = client._driver
        self._remove: Callable[[], None] | None = client.subscribe(
            self._queue.put_nowait, kinds=kinds, motor=motor)
        self._ended = False

    def __aiter__(self) -> EventStream:
        return self

    async def __anext__(self) -> MotorEvent:
        if self._ended and self._queue.empty():
            raise StopAsyncIteration
        if self._queue.empty():      # a fast port's time moves while the stream waits
            await self._driver.advance_until(lambda: not self._queue.empty())
        item = await self._queue.get()
        if item is None or isinstance(item, BaseException):
            self._ended = True
            if isinstance(item, BaseException):
                raise item
            raise StopAsyncIteration
        return item

    def end(self, error: BaseException | None = None) -> None:
        """No more events (the connection closed or failed: ``error``)."""
        if self._remove is not None:
            self._remove()
            self._remove = None
            self._queue.put_nowait(error)

    async def aclose(self) -> None:
        """Stop receiving events."""
        self.end()

    async def __aenter__(self) -> EventStream:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.aclose()


class AsyncCoolMuscle(AsyncMotor):
    """An asyncio connection to a chain, and the motor it was opened for."""

    def __init__(self, port: Any, *, motor: int = 1, timeout: float = ops.DEFAULT_TIMEOUT,
                 firmware: str | None = None, poll_interval: float = ops.DEFAULT_POLL,
                 own_port: bool = True) -> None:
        session = ops.Session(timeout=timeout, firmware=firmware, poll_interval=poll_interval)
        super().__init__(AsyncDriver(port, session), motor)
        self.port = port
        self._own_port = own_port
        self._motors: dict[int, AsyncMotor] = {motor: self}
        self._streams: weakref.WeakSet[EventStream] = weakref.WeakSet()
        self._driver.on_failure.append(self._failed)
        try:
            port.reset_input_buffer()
        except (serial.SerialException, OSError, AttributeError):
            pass
        self._driver.start()

    def motor(self, motor_id: int) -> AsyncMotor:
        """The handle for another motor ID of the chain."""
        motor_id = args.motor_id(motor_id)
        if motor_id not in self._motors:
            self._motors[motor_id] = AsyncMotor(self._driver, motor_id)
        return self._motors[motor_id]

    @property
    def echo(self) -> bool | None:
        """Whether the motor echoes, as learned."""
        return self._session.protocol.echo

    @property
    def delimiter(self) -> bytes | None:
        """The motor's line end as seen."""
        return self._session.protocol.delimiter

    def subscribe(self, listener: Listener, *, kinds: Iterable[str] | None = None,
                  motor: int | None = None) -> Callable[[], None]:
        """Call ``listener(event)`` in the loop for each event as it arrives."""
        wanted = frozenset(kinds) if kinds is not None else None

        def accepts(event: MotorEvent) -> bool:
            return (wanted is None or event.kind in wanted) and \
                (motor is None or event.motor == motor)
        entry = (listener, accepts)
        self._driver.listeners.append(entry)

        def remove() -> None:
            if entry in self._driver.listeners:
                self._driver.listeners.remove(entry)
        return remove

    def add_failure_listener(self, listener: Callable[[BaseException], None]
                             ) -> Callable[[], None]:
        """Call ``listener(error)`` in the loop once the port fails (the peer closed the
        connection, the cable was pulled): the :class:`~coolmuscle.errors.TransportError`
        every later call raises.  Returns a function that removes it."""
        self._driver.on_failure.append(listener)

        def remove() -> None:
            if listener in self._driver.on_failure:
                self._driver.on_failure.remove(listener)
        return remove

    def add_tap(self, tap: Callable[[str, bytes], None]) -> Callable[[], None]:
        """Call ``tap(">", data)`` for every byte written and ``tap("<", data)`` for every
        byte read (a session recorder); returns a function that removes it."""
        self._driver.taps.append(tap)

        def remove() -> None:
            if tap in self._driver.taps:
                self._driver.taps.remove(tap)
        return remove

    def write_line(self, line: str) -> None:
        """Send one line as typed, with no exchange: whatever the motor answers arrives
        as events (kind ``unsolicited`` for replies).  For terminals."""
        self._driver.write(self._session.protocol.encode([line]))

    def events(self, *, kinds: Iterable[str] | None = None,
               motor: int | None = None) -> EventStream:
        """Events as they arrive, from this call on: ``async for event in m.events()``.

        The subscription starts when ``events()`` is called, not at the first
        iteration, so nothing said in between is missed; ``aclose()`` (or leaving an
        ``async with``) ends it.
        """
        stream = EventStream(self, kinds, motor)
        self._streams.add(stream)
        if self._driver.failure is not None:
            stream.end(self._driver.failure)
        return stream

    async def wait_event(self, *, kind: str | None = None, motor: int | None = None,
                         timeout: float = ops.DEFAULT_WAIT) -> MotorEvent:
        """The next matching event; :class:`CoolMuscleTimeout` after ``timeout``."""
        timeout = args.seconds("timeout", timeout)  # type: ignore[assignment]
        since = self._session.protocol.seq
        request = ops.Listen(since, lambda e: (kind is None or e.kind == kind) and
                             (motor is None or e.motor == motor), timeout)
        event: MotorEvent | None = await self._driver._do(request)
        if event is None:
            raise CoolMuscleTimeout(f"no {kind or 'event'} within {timeout:g} s")
        return event

    def _failed(self, error: BaseException) -> None:
        for stream in list(self._streams):
            stream.end(error)

    async def close(self) -> None:
        """Stop the reader and close the port (when this connection opened it); the
        event streams end."""
        for stream in list(self._streams):
            stream.end()
        await asyncio.to_thread(self._driver.close)
        if self._own_port:
            self.port.close()

    async def __aenter__(self) -> AsyncCoolMuscle:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


async def connect_async(url: str | Any, *, baudrate: int = 38400, motor: int = 1,
                        timeout: float = ops.DEFAULT_TIMEOUT, firmware: str | None = None,
                        poll_interval: float = ops.DEFAULT_POLL,
                        **serial_options: Any) -> AsyncCoolMuscle:
    """As :func:`coolmuscle.connect`, for asyncio."""
    if not isinstance(url, str) and not (hasattr(url, "write") and hasattr(url, "read")):
        raise InvalidArgumentError(f"connect() takes a URL or an open port, not {url!r}")
    args.motor_id(motor)                # the arguments, before a port is opened
    ops.Session(timeout=timeout, firmware=firmware, poll_interval=poll_interval)
    if isinstance(url, str):
        port = await asyncio.to_thread(open_port, url, baudrate=baudrate, **serial_options)
        own = True
    else:
        port, own = url, False
    return AsyncCoolMuscle(port, motor=motor, timeout=timeout, firmware=firmware,
                           poll_interval=poll_interval, own_port=own)
