"""Client operations as sans-IO generators, shared by the sync and asyncio clients.

An operation is a generator that *yields requests* and receives their results; it
never touches a port or a clock.  A driver (:mod:`coolmuscle.client.sync`,
:mod:`coolmuscle.client.aio`) runs it::

    def position(session, motor):
        reply = yield from query(session, motor, f"?96.{motor}", "Px")   # 6.6 ?96
        return reply.int_value()

Requests: :class:`~coolmuscle.client.protocol.Exchange` (send lines, collect the
answer; the driver raises :class:`~coolmuscle.errors.CoolMuscleTimeout` when its
timeout passes), :class:`Listen` (the next event that matches, or ``None``),
:class:`Pause` (keep reading for a while) and :class:`Now` (the driver's clock).

A command that prints nothing is followed by a *fence*, a query whose reply is never a
report (``?96.n``), or ``?99.n`` when the status after the command is wanted: errors
the command reports (``errorNN.n``, ch. 3 K23 16) arrive before the fence's reply, so
every command learns whether it failed.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import Any, TypeVar

from ..errors import (
    AlarmError,
    CoolMuscleTimeout,
    InvalidArgumentError,
    MotionInterruptedError,
    ProtocolError,
)
from ..motor.status import ALARM_BITS, Report, Ux
from . import args
from .protocol import Exchange, MotorEvent, Protocol
from .replies import Received, parse_int_reply, parse_io_word, parse_listing

T = TypeVar("T")

#: What an operation yields.
Request = Any
Op = Generator[Request, Any, T]

#: Default seconds to wait for a reply (``timeout=`` of :func:`coolmuscle.connect`).
DEFAULT_TIMEOUT = 1.0
#: Default seconds ``wait_in_position`` waits.
DEFAULT_WAIT = 30.0
#: Seconds between ``?99`` polls when the motor does not report in-position (K23).
DEFAULT_POLL = 0.05
#: With reports on, a ``?99`` is still sent after this long without one (a lost report).
REPORT_GUARD = 1.0
#: Alarms and push error: the motor cannot reach the target (6.6 ?99).
_FAILED = int(ALARM_BITS | Ux.PUSH_ERROR)


@dataclass(frozen=True)
class Listen:
    """Wait up to ``timeout`` s for an event after ``since`` that ``match`` accepts."""

    since: int
    match: Callable[[MotorEvent], bool]
    timeout: float


@dataclass(frozen=True)
class Pause:
    """Keep reading (events are delivered) for ``seconds``; never an error.

    ``shared``: another thread's request may go out meanwhile (a wait between polls);
    not inside a bank upload, whose lines would then hold it (2.2.2)."""

    seconds: float
    shared: bool = False


@dataclass(frozen=True)
class Now:
    """The driver's clock in seconds (virtual for ``coolmuscle://?mode=fast``)."""


@dataclass
class MotorCache:
    """What the client knows about one motor without asking again."""

    params: dict[int, int] = field(default_factory=dict)   # K values read or written
    firmware: str | None = None


@dataclass
class Session:
    """Sans-IO state of one connection: the protocol, per-motor knowledge, defaults."""

    protocol: Protocol = field(default_factory=Protocol)
    timeout: float = DEFAULT_TIMEOUT
    firmware: str | None = None
    poll_interval: float = DEFAULT_POLL
    motors: dict[int, MotorCache] = field(default_factory=dict)
    #: motor -> seq of the status reply taken right after the last motion command
    motion_seq: dict[int, int] = field(default_factory=dict)
    #: a bank definition is open on the host line (``B#`` sent, no ``END`` yet)
    defining: bool = False

    def __post_init__(self) -> None:
        self.timeout = args.seconds("timeout", self.timeout)  # type: ignore[assignment]
        self.poll_interval = args.seconds("poll_interval",  # type: ignore[assignment]
                                          self.poll_interval)
        if self.firmware is not None:
            from ..motor.state.firmware import get_firmware  # noqa: PLC0415
            try:
                get_firmware(self.firmware)
            except (LookupError, TypeError):
                raise InvalidArgumentError(f"unknown firmware {self.firmware!r} "
                                           "(cm2, rt3 or cm1)") from None

    def cache(self, motor: int) -> MotorCache:
        return self.motors.setdefault(motor, MotorCache())


# -- exchanges -----------------------------------------------------------------------

def exchange(session: Session, lines: tuple[str, ...], done: Callable[[Received], bool],
             motor: int | None, wanted: str, timeout: float | None = None,
             keep_echo: str | None = None) -> Op[Exchange]:
    """Send ``lines``; return the completed exchange; raise the first reported error.

    Refused while a bank definition is open on the line (``B#``/``L#`` sent with
    ``send``, no ``END`` yet): the motor would store the lines in the bank (2.2.2)."""
    if session.defining:
        raise InvalidArgumentError("a bank definition is open on the line: send its END "
                                   "(or an empty line) before other commands (2.2.2)")
    ex = yield Exchange(tuple(lines), done, motor, wanted,
                        timeout=session.timeout if timeout is None else timeout,
                        keep_echo=keep_echo)
    if ex.errors:
        raise ex.errors[0]
    done_exchange: Exchange = ex
    return done_exchange


def named(name: str, motor: int) -> Callable[[Received], bool]:
    """Completes on ``NAME.motor=...`` (6.6 reply form)."""
    return lambda line: line.name == name and line.motor == motor


def query(session: Session, motor: int, text: str, name: str,
          timeout: float | None = None) -> Op[Received]:
    """A one-line query whose reply is ``NAME.motor=VALUE``; returns that line."""
    ex = yield from exchange(session, (text,), named(name, motor), motor,
                             f"{name}.{motor}= reply", timeout)
    return ex.lines[-1]


def query_int(session: Session, motor: int, number: int, name: str) -> Op[int]:
    """``?number.motor`` -> the integer of ``NAME.motor=`` (6.6)."""
    line = yield from query(session, motor, f"?{number}.{motor}", name)
    return parse_int_reply(line, name, motor)


def fenced(session: Session, motor: int, lines: tuple[str, ...], *, status: bool = False,
           timeout: float | None = None, listed: bool = False) -> Op[list[Received]]:
    """Send ``lines`` then a fence (``?96`` or, with ``status``, ``?99``); return the
    lines answered before the fence's reply (the fence's reply last).

    ``listed``: the answer may hold the fence's own text (a bank listing line, 6.6):
    the echo of the fence is then the last such line before its reply, and only it is
    left out."""
    if status:
        fence, done = f"?99.{motor}", lambda l: l.kind == "status" and l.motor == motor
    else:
        fence, done = f"?96.{motor}", named("Px", motor)
    ex = yield from exchange(session, (*lines, fence), done, motor, f"reply to {fence}",
                             timeout, keep_echo=fence if listed else None)
    if status:
        session.motion_seq[motor] = ex.end_seq
    answer = ex.lines
    if listed and session.protocol.echo is True:
        last = max((i for i, line in enumerate(answer[:-1]) if line.text == fence),
                   default=None)
        if last is not None:
            answer = answer[:last] + answer[last + 1:]
    return answer


def listing(session: Session, motor: int, text: str,
            timeout: float | None = None) -> Op[list[str]]:
    """A query answered by several lines (``?90``, ``?A``, ``?1.n``): the lines, in order."""
    lines = yield from fenced(session, motor, (text,), timeout=timeout, listed=True)
    return [line.text for line in lines[:-1] if line.kind != "error"]


# -- typed queries (6.6) ----------------------------------------------------------------

def status(session: Session, motor: int) -> Op[Ux]:
    """``?99`` -> Ux flags."""
    value = yield from query_int(session, motor, 99, "Ux")
    return Ux(value)


def io_word(session: Session, motor: int, number: int, name: str) -> Op[int]:
    """``?70`` inputs / ``?50`` outputs: bit 0 = input/output 1."""
    line = yield from query(session, motor, f"?{number}.{motor}", name)
    return parse_io_word(line)


def direct_data(session: Session, motor: int) -> Op[dict[str, int]]:
    """``?.n``: the direct-mode P, S, A, M (2.1 "?1")."""
    lines = yield from listing(session, motor, f"?.{motor}")
    items = parse_listing(lines)
    try:
        return {name: int(value) for name, value in items.items()}
    except ValueError:
        raise ProtocolError(f"garbled direct data {lines!r}") from None


def params(session: Session, motor: int) -> Op[dict[int, int]]:
    """``?90``: K20..K89 (6.6)."""
    lines = yield from listing(session, motor, f"?90.{motor}")
    values: dict[int, int] = {}
    for name, value in parse_listing(lines).items():
        if not (name.startswith("K") and name[1:].isdigit()):
            raise ProtocolError(f"garbled ?90 item {name}={value}")
        try:
            values[int(name[1:])] = int(value)
        except ValueError:
            raise ProtocolError(f"garbled ?90 item {name}={value}") from None
    session.cache(motor).params.update(values)
    return values


def param(session: Session, motor: int, k: int, *, cached: bool = False) -> Op[int]:
    """``K#.n`` alone: the value of K# (ch. 3; 6.6 reply form ``K23.1=1``)."""
    cache = session.cache(motor).params
    if cached and k in cache:
        return cache[k]
    line = yield from query(session, motor, f"K{k}.{motor}", f"K{k}")
    value = parse_int_reply(line, f"K{k}", motor)
    cache[k] = value
    return value


# -- waiting for in-position ------------------------------------------------------------------

def settled(motor: int, ux: int) -> bool:
    """True when Ux says in position; raise when the motor cannot get there (6.6 ?99)."""
    if ux & _FAILED:
        raise AlarmError(ux, f"motor {motor} alarm: Ux.{motor}={ux} ({Ux(ux)!r})")
    if ux & Ux.EMERGENCY_STOP:
        raise MotionInterruptedError(ux, f"motor {motor}: emergency stop (Ux.{motor}={ux})")
    if ux & Ux.MOTOR_FREE:
        raise MotionInterruptedError(ux, f"motor {motor} is free (Ux.{motor}={ux})")
    return bool(ux & Ux.IN_POSITION)


def _status_event(motor: int) -> Callable[[MotorEvent], bool]:
    return lambda e: e.kind == "status" and e.motor == motor and e.value is not None


def wait_in_position(session: Session, motor: int, timeout: float) -> Op[Ux]:
    """Until Ux shows in-position (8) after the last motion command; alarms raise.

    With K23 function 1 the motor reports ``Ux.n=`` by itself and the client just
    listens (a ``?99`` goes out only after :data:`REPORT_GUARD` s of silence);
    otherwise it polls ``?99`` every ``poll_interval`` s (ch. 3 K23, 6.6 ?99).
    """
    timeout = args.seconds("timeout", timeout)  # type: ignore[assignment]
    start = yield Now()
    deadline = start + timeout
    since = session.motion_seq.get(motor, 0)
    seen = session.protocol.status_seen.get(motor)
    if seen is not None and seen[0] >= since:
        if settled(motor, seen[1]):
            return Ux(seen[1])
        since = seen[0]
    reports = (yield from param(session, motor, 23, cached=True)) & Report.IN_POSITION_AND_ALARM
    while True:
        remaining = deadline - (yield Now())
        if remaining <= 0:
            raise CoolMuscleTimeout(f"motor {motor} not in position within {timeout:g} s")
        if reports:
            event = yield Listen(since, _status_event(motor), min(remaining, REPORT_GUARD))
            if event is not None:
                since = event.seq
                if settled(motor, event.value):
                    return Ux(event.value)
                continue
        else:
            yield Pause(min(remaining, session.poll_interval), shared=True)
        remaining = deadline - (yield Now())
        if remaining <= 0:
            continue
        try:
            line = yield from query(session, motor, f"?99.{motor}", "Ux",
                                    timeout=min(session.timeout, remaining))
        except CoolMuscleTimeout:
            raise CoolMuscleTimeout(f"motor {motor} not in position within {timeout:g} s "
                                    f"(no answer to ?99.{motor})") from None
        since = session.protocol.status_seen.get(motor, (since, 0))[0]
        if settled(motor, parse_int_reply(line, "Ux", motor)):
            return Ux(parse_int_reply(line, "Ux", motor))
