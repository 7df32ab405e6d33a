"""The blocking client: :func:`connect`, :class:`CoolMuscle` and :class:`Motor`.

::

    from coolmuscle import connect
    with connect("socket://127.0.0.1:5150") as m:        # or "/dev/ttyUSB0", "coolmuscle://"
        m.move_to(10000, speed=100, accel=100)
        m.wait_in_position(timeout=5)
        print(m.position, m.status)
        m2 = m.motor(2)                                   # another motor of the chain

A :class:`Motor` is one motor ID on the chain; :class:`CoolMuscle` is the connection
and also the motor it was opened for (ID1 by default).  Every method sends CML
(cml-users-guide.txt ch. 2, 3, 6) and reads the 6.6 replies; each call is bounded by
its timeout.  Errors: :class:`~coolmuscle.errors.CoolMuscleTimeout`,
:class:`~coolmuscle.errors.OutOfRangeError` (error00, or refused before sending),
:class:`~coolmuscle.errors.CmlSyntaxError` (error01) and the other
:class:`~coolmuscle.errors.MotorError` numbers, :class:`~coolmuscle.errors.AlarmError`
(with the Ux value), :class:`~coolmuscle.errors.ProtocolError` (an unreadable reply),
:class:`~coolmuscle.errors.TransportError` (the port failed).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import serial

from ..errors import CoolMuscleTimeout, InvalidArgumentError, TransportError
from ..frontends.urlhandler import register as register_url_handler
from ..motor.status import Ux
from . import args, banks, commands, ops
from .driver import Listener, SyncDriver
from .program import ProgramFile, load_program, parse_program
from .protocol import MotorEvent
from .replies import Version, parse_version

__all__ = ["connect", "CoolMuscle", "Motor", "open_port"]


def open_port(url: str, *, baudrate: int = 38400, **kwargs: Any) -> Any:
    """Open any pyserial URL or device path; a ``coolmuscle://`` URL registers its
    handler with pyserial first (:func:`coolmuscle.register_url_handler`)."""
    if url.lower().startswith("coolmuscle://"):
        register_url_handler()
    _check_socket_url(url)
    try:
        return serial.serial_for_url(url, baudrate=baudrate, timeout=ops.DEFAULT_TIMEOUT,
                                     **kwargs)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise TransportError(f"cannot open {url}: {exc}") from exc


def _check_socket_url(url: str) -> None:
    """``socket://`` needs a host and a port (pyserial's own error is a comparison)."""
    if not url.lower().startswith("socket://"):
        return
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = None
    if not parts.hostname or port is None:
        raise TransportError(f"cannot open {url}: a socket URL is socket://HOST:PORT, e.g. "
                             "socket://127.0.0.1:5150 (what 'coolmuscle sim' serves)")


def program_of(source: str | Path | ProgramFile) -> ProgramFile:
    """A :class:`ProgramFile` from a path, CML text or an already parsed file.

    A one-line str is a path when such a file exists; one that names a ``.cml`` file
    must name an existing one (a mistyped path is not sent to the motor as CML)."""
    if isinstance(source, ProgramFile):
        return source
    if isinstance(source, Path):
        return load_program(source)
    if not isinstance(source, str):
        raise InvalidArgumentError(f"upload() takes a path, CML text or a ProgramFile, "
                                   f"not {source!r}")
    if "\n" not in source:
        path = Path(source)
        if path.is_file():
            return load_program(path)
        if source.strip().lower().endswith(".cml"):
            raise InvalidArgumentError(f"no such program file: {source}")
    return parse_program(source)


class Motor:
    """One motor ID on the chain (sync).  Obtain with :meth:`CoolMuscle.motor`."""

    def __init__(self, driver: SyncDriver, motor_id: int) -> None:
        self._driver = driver
        self.id = args.motor_id(motor_id)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} ID{self.id}>"

    def _run(self, op: ops.Op[ops.T]) -> ops.T:
        return self._driver.run(op)

    @property
    def _session(self) -> ops.Session:
        return self._driver.session

    # -- raw CML ---------------------------------------------------------------------
    def send(self, line: str, *, timeout: float | None = None) -> list[str]:
        """Send one CML line; return the lines the motor answered (echo removed).

        The line is followed by a ``?96`` fence so that its errors and replies are
        complete when this returns (``errorNN`` lines raise).  Inside a bank
        definition (after ``B#``/``L#``) lines go alone, paced by their echo.
        """
        answer = self._run(banks.send_line(self._session, self.id, line, timeout))
        self._forget(line)
        return answer

    def _forget(self, line: str) -> None:
        """A raw line may have changed K23/K37: re-read them when next needed."""
        if "K" in line.upper():
            self._session.cache(self.id).params.clear()

    # -- typed queries (6.6) -----------------------------------------------------------
    def get_position(self) -> int:
        """``?96``: current position Px, pulses."""
        return self._run(ops.query_int(self._session, self.id, 96, "Px"))

    def get_speed(self) -> int:
        """``?97``: current speed Sx, in K37 speed units."""
        return self._run(ops.query_int(self._session, self.id, 97, "Sx"))

    def get_torque(self) -> int:
        """``?98``: current torque Ix."""
        return self._run(ops.query_int(self._session, self.id, 98, "Ix"))

    def get_position_error(self) -> int:
        """``?95``: position error Pe, pulses."""
        return self._run(ops.query_int(self._session, self.id, 95, "Pe"))

    def get_status(self) -> Ux:
        """``?99``: Ux decoded as flags (``Ux.IN_POSITION in m.status``)."""
        return self._run(ops.status(self._session, self.id))

    def get_inputs(self) -> int:
        """``?70``: input word, bit 0 = input 1."""
        return self._run(ops.io_word(self._session, self.id, 70, "IN"))

    def get_outputs(self) -> int:
        """``?50``: output word, bit 0 = output 1."""
        return self._run(ops.io_word(self._session, self.id, 50, "OUT"))

    def get_output(self, number: int) -> bool:
        """``?51``..``?54``: one output."""
        return self._run(commands.output(self._session, self.id, number))

    def get_temperature(self) -> int:
        """``?71``: driver temperature, °C."""
        return self._run(ops.query_int(self._session, self.id, 71, "Temp"))

    def get_voltage(self) -> float:
        """``?72``: supply voltage in volts (the motor reports 0.1 V units)."""
        return self._run(ops.query_int(self._session, self.id, 72, "VSEN")) / 10

    def get_analog(self) -> int:
        """``?74``: analog input, 0..1023 for 0..5 V."""
        return self._run(ops.query_int(self._session, self.id, 74, "ADI0"))

    def get_encoder_count(self) -> int:
        """``?76``: external encoder counter."""
        return self._run(ops.query_int(self._session, self.id, 76, "Ecnt"))

    def get_version(self) -> Version:
        """``?85``: the version title, parsed."""
        return parse_version(self._run(commands._version_line(self._session, self.id)))

    def get_direct_data(self) -> dict[str, int]:
        """``?.n``: direct-mode ``{"P":…, "S":…, "A":…, "M":…}`` (2.1)."""
        return self._run(ops.direct_data(self._session, self.id))

    position = property(get_position)
    speed = property(get_speed)
    torque = property(get_torque)
    position_error = property(get_position_error)
    status = property(get_status)
    inputs = property(get_inputs)
    outputs = property(get_outputs)
    temperature = property(get_temperature)
    voltage = property(get_voltage)
    analog = property(get_analog)
    encoder_count = property(get_encoder_count)
    version = property(get_version)

    # -- registers and parameters -------------------------------------------------------
    def read_register(self, kind: str, index: int = 0) -> int | str:
        """A data register (6.2): ``read_register("P", 15)``; index 0 is direct data."""
        return self._run(commands.read_register(self._session, self.id, kind, index))

    def write_register(self, kind: str, index: int, value: int | str) -> None:
        """Write and read back a data register; :class:`OutOfRangeError` if refused."""
        self._run(commands.write_register(self._session, self.id, kind, index, value))

    def read_param(self, k: int) -> int:
        """``K#.n``: one K parameter (ch. 3); a K number the firmware lacks is refused."""
        return self._run(commands.read_param(self._session, self.id, k))

    def read_params(self) -> dict[int, int]:
        """``?90``: K20..K89 (6.6)."""
        return self._run(ops.params(self._session, self.id))

    def write_param(self, k: int, value: int) -> None:
        """Set K``k`` after checking it against the firmware's table 6.1; read back."""
        self._run(commands.write_param(self._session, self.id, k, value))

    # -- motion (2.1.1, 2.1.2) ------------------------------------------------------------
    def move_to(self, position: int, speed: int | None = None, accel: int | None = None,
                *, torque: int | None = None) -> Ux:
        """``S.n``, ``A.n``, ``M.n``, ``P.n=position``, ``^.n``; returns Ux just after."""
        return self._run(commands.move(self._session, self.id, position, speed=speed,
                                       accel=accel, torque=torque))

    def move_by(self, distance: int, speed: int | None = None, accel: int | None = None,
                *, torque: int | None = None) -> Ux:
        """``P.n+=distance`` (relative to the current position, 2.1.1), ``^.n``."""
        return self._run(commands.move(self._session, self.id, distance, relative=True,
                                       speed=speed, accel=accel, torque=torque))

    def run(self, speed: int, accel: int | None = None) -> Ux:
        """Continuous rotation (``P=1000000000``); negative speed turns CCW (2.1.1)."""
        return self._run(commands.run_continuous(self._session, self.id, speed, accel))

    def _status_command(self, text: str) -> Ux:
        return self._run(commands.motion(self._session, self.id, [text]))

    def stop(self) -> Ux:
        """``]1.n``: decelerate this motor to a stop (2.1.2)."""
        return self._status_command(f"]1.{self.id}")

    def emergency_stop(self) -> Ux:
        """``*``: every motor of the chain stops at maximum deceleration (2.1.2)."""
        return self._status_command("*")

    def release_emergency_stop(self) -> Ux:
        """``*1``: cancel the emergency stop and enable the motors (2.1.2)."""
        return self._status_command("*1")

    def enable(self) -> Ux:
        """``(.n``: servo on."""
        return self._status_command(f"(.{self.id}")

    def free(self) -> Ux:
        """``).n``: motor free."""
        return self._status_command(f").{self.id}")

    def origin_search(self) -> Ux:
        """``|.n``: search the origin per K42, K43, K45, K46 (5.3)."""
        return self._status_command(f"|.{self.id}")

    def go_origin(self) -> Ux:
        """``|1.n``: move to position 0."""
        return self._status_command(f"|1.{self.id}")

    def set_origin(self) -> Ux:
        """``|2.n``: the current position becomes 0."""
        return self._status_command(f"|2.{self.id}")

    def wait_in_position(self, timeout: float = ops.DEFAULT_WAIT) -> Ux:
        """Wait for in-position after the last motion command (events or polling)."""
        return self._run(ops.wait_in_position(self._session, self.id, timeout))

    # -- outputs ---------------------------------------------------------------------
    def set_output(self, number: int, on: bool = True) -> None:
        """``O#.n`` / ``F#.n`` (the output's K34 digit must be 3, general use)."""
        self._run(commands.set_output(self._session, self.id, number, on))

    # -- banks ---------------------------------------------------------------------
    def upload(self, source: str | Path | ProgramFile, *, verify: bool = True,
               progress: banks.Progress | None = None, check: bool = True,
               line_delay: float = banks.DEFAULT_LINE_DELAY) -> banks.UploadResult:
        """Send a ``.cml`` file (path, text or parsed) and verify banks by readback.

        With ``check`` an upload with errors or differences raises
        :class:`~coolmuscle.client.banks.UploadError` (it carries the result).
        """
        result = self._run(banks.upload(self._session, program_of(source), verify=verify,
                                        line_delay=line_delay, progress=progress))
        self._session.cache(self.id).params.clear()
        if check and not result.ok:
            raise banks.UploadError(result)
        return result

    def read_bank(self, number: int, *, ladder: bool = False) -> list[str]:
        """``?#.n`` / ``?L#.n``: a bank's lines as the motor prints them (6.6)."""
        return self._run(banks.read_bank(self._session, self.id, number, ladder))

    def read_all_banks(self) -> dict[str, list[str]]:
        """``?1000.n``: every bank, ``{"B1.1": [lines], ...}`` (6.6)."""
        return self._run(banks.all_banks(self._session, self.id))

    def start_bank(self, number: int) -> None:
        """``[#.n``: run program bank ``number`` (2.1.2)."""
        number = self._run(commands.bank_number(self._session, self.id, number))
        self.send(f"[{number}.{self.id}")

    def pause_bank(self) -> None:
        """``]``: stop all motors and pause the program bank (2.1.2)."""
        self.send("]")

    def stop_bank(self) -> None:
        """``]`` twice: the program bank is terminated (2.1.2)."""
        self.send("]")
        self.send("]")

    def start_ladder(self, number: int) -> None:
        """``[L#.n``: run ladder bank ``number`` in the background."""
        number = self._run(commands.bank_number(self._session, self.id, number, ladder=True))
        self.send(f"[L{number}.{self.id}")

    def stop_ladder(self) -> None:
        """``]L.n``: stop the ladder bank."""
        self.send(f"]L.{self.id}")

    def save(self, timeout: float = 5.0) -> None:
        """``$.n``: save parameters, data and banks; waits for ``saved.n`` (2.1.2)."""
        self._run(banks.save(self._session, self.id, timeout))


class CoolMuscle(Motor):
    """A connection to a chain, and the motor (ID ``motor``) it was opened for."""

    def __init__(self, port: Any, *, motor: int = 1, timeout: float = ops.DEFAULT_TIMEOUT,
                 firmware: str | None = None, poll_interval: float = ops.DEFAULT_POLL,
                 own_port: bool = True) -> None:
        session = ops.Session(timeout=timeout, firmware=firmware, poll_interval=poll_interval)
        super().__init__(SyncDriver(port, session), motor)
        self.port = port
        self._own_port = own_port
        self._motors: dict[int, Motor] = {motor: self}
        try:
            port.reset_input_buffer()
        except (serial.SerialException, OSError, AttributeError):
            pass

    def motor(self, motor_id: int) -> Motor:
        """The handle for another motor ID of the chain (1..15)."""
        motor_id = args.motor_id(motor_id)
        if motor_id not in self._motors:
            self._motors[motor_id] = Motor(self._driver, motor_id)
        return self._motors[motor_id]

    @property
    def echo(self) -> bool | None:
        """Whether the motor echoes (K23 without 8), as learned; ``None`` until known."""
        return self._session.protocol.echo

    @property
    def delimiter(self) -> bytes | None:
        """The motor's line end (K70) as seen: ``b"\\r\\n"`` or ``b"\\r"``."""
        return self._session.protocol.delimiter

    # -- events ---------------------------------------------------------------------
    def subscribe(self, listener: Listener, *, kinds: Iterable[str] | None = None,
                  motor: int | None = None) -> Callable[[], None]:
        """Call ``listener(event)`` for each :class:`MotorEvent` (``Ux``, ``IN``, ``OUT``,
        messages...) as it is read, during any call or :meth:`poll`.  Returns a
        function that unsubscribes."""
        wanted = frozenset(kinds) if kinds is not None else None

        def accepts(event: MotorEvent) -> bool:
            return (wanted is None or event.kind in wanted) and \
                (motor is None or event.motor == motor)
        return self._driver.subscribe(listener, accepts)

    def poll(self, seconds: float = 0.0) -> list[MotorEvent]:
        """Read for ``seconds`` (0: what is there) and return the events that came."""
        seconds = args.seconds("seconds", seconds)  # type: ignore[assignment]
        with self._driver.turn():
            events = self._driver.pump(0.0)
            if seconds > 0:
                events += self._driver._pump_for(seconds)
            return events

    def wait_event(self, *, kind: str | None = None, motor: int | None = None,
                   timeout: float = ops.DEFAULT_WAIT) -> MotorEvent:
        """The next event of ``kind`` (and ``motor``); :class:`CoolMuscleTimeout` if none."""
        timeout = args.seconds("timeout", timeout)  # type: ignore[assignment]
        since = self._session.protocol.seq

        def match(event: MotorEvent) -> bool:
            return (kind is None or event.kind == kind) and (motor is None or
                                                             event.motor == motor)
        event = self._driver.run(_listen(since, match, timeout))
        if event is None:
            raise CoolMuscleTimeout(f"no {kind or 'event'} within {timeout:g} s")
        return event

    # -- life cycle -----------------------------------------------------------------
    def close(self) -> None:
        """Close the port (when this connection opened it)."""
        if self._own_port:
            self.port.close()

    def __enter__(self) -> CoolMuscle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _listen(since: int, match: Callable[[MotorEvent], bool],
            timeout: float) -> ops.Op[MotorEvent | None]:
    event: MotorEvent | None = yield ops.Listen(since, match, timeout)
    return event


def connect(url: str | Any, *, baudrate: int = 38400, motor: int = 1,
            timeout: float = ops.DEFAULT_TIMEOUT, firmware: str | None = None,
            poll_interval: float = ops.DEFAULT_POLL, **serial_options: Any) -> CoolMuscle:
    """Open ``url`` (any pyserial URL or device, or an open port object) and connect.

    ``baudrate`` must match K20 on a real motor (38400 by default, ch. 3 K20);
    ``timeout`` bounds each reply; ``firmware`` (``cm2``, ``rt3``, ``cm1``) skips
    reading ``?85`` to pick the parameter table used for validation.
    """
    if not isinstance(url, str) and not (hasattr(url, "write") and hasattr(url, "read")):
        raise InvalidArgumentError(f"connect() takes a URL or an open port, not {url!r}")
    args.motor_id(motor)                # the arguments, before a port is opened
    ops.Session(timeout=timeout, firmware=firmware, poll_interval=poll_interval)
    if isinstance(url, str):
        port = open_port(url, baudrate=baudrate, **serial_options)
        own = True
    else:
        port, own = url, False
    return CoolMuscle(port, motor=motor, timeout=timeout, firmware=firmware,
                      poll_interval=poll_interval, own_port=own)
