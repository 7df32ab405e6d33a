"""Typed commands: validated against the firmware tables, sent, confirmed (sans-IO).

Values are checked before anything is sent, with the same tables the virtual motor
uses (:mod:`coolmuscle.motor.state.firmware` for K parameters, table 6.1;
:class:`coolmuscle.motor.state.memory.Memory` for data ranges, 6.2), so a bad value raises
:class:`~coolmuscle.errors.OutOfRangeError` on the host instead of being silently
refused by a motor whose K23 does not include 16.  Writes are then read back: a value
the motor did not take raises too, whatever K23 says.

Motion (2.1.1, 2.1.2): ``S.n``/``A.n``/``M.n``/``P.n`` then ``^.n``, followed by
``?99.n`` so that the status right after the command is known to
:func:`coolmuscle.client.ops.wait_in_position`.
"""

from __future__ import annotations

from ..errors import CoolMuscleTimeout, InvalidArgumentError, OutOfRangeError
from ..motor.programs.queries import format_value
from ..motor.state.firmware import Firmware, get_firmware
from ..motor.state.memory import Memory, NoSuchRegisterError
from ..motor.state.units import resolution
from ..motor.status import Ux
from . import args
from .ops import Op, Session, exchange, fenced, param, query
from .replies import Received, parse_int_reply, parse_version

__all__ = ["firmware", "read_register", "write_register", "write_param", "motion",
           "move_lines", "register_name", "REGISTER_KINDS"]

#: Data registers the client reads and writes (6.2); K goes through write_param.
REGISTER_KINDS = ("P", "S", "A", "M", "T", "V", "N", "R", "H")


def firmware(session: Session, motor: int) -> Op[Firmware]:
    """The profile used for validation: ``firmware=`` of connect, else from ``?85``."""
    cache = session.cache(motor)
    name = cache.firmware or session.firmware
    if name is None:
        line = yield from _version_line(session, motor)
        name = parse_version(line).profile()
    try:
        found = get_firmware(name)
    except LookupError:
        raise InvalidArgumentError(f"unknown firmware {name!r} (cm2, rt3 or cm1)") from None
    cache.firmware = name
    return found


def _version_line(session: Session, motor: int) -> Op[str]:
    ex = yield from exchange(session, (f"?85.{motor}",),
                             lambda l: l.kind == "version" and l.motor == motor, motor,
                             "?85 version title")
    return ex.lines[-1].text


def register_name(kind: str, index: int, motor: int) -> str:
    """``P15.1``; index 0 is written ``P.1``, the direct-mode data (2.1)."""
    return f"{kind}{index if index else ''}.{motor}"


def _memory(fw: Firmware, k37: int) -> Memory:
    return Memory(fw, k37=k37)


def _check_index(fw: Firmware, kind: str, index: int) -> None:
    top = fw.registers.limit(kind)
    if kind in ("P", "N", "R") and fw.can_allocate and fw.pnr_pool:
        top = fw.pnr_pool  # 2.1.2 allocation may give one register up to 600
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index <= top:
        raise NoSuchRegisterError(f"{kind}{index} does not exist ({kind}0..{kind}{top})")


def _surely_there(fw: Firmware, kind: str, index: int) -> bool:
    """Whether the motor has memory ``kind`` ``index`` whatever it was told: on the R
    type an allocation (2.1.2 ``\\P``, ``\\N``) may leave any P, N or R out but
    index 0 (direct mode)."""
    return index == 0 or kind not in ("P", "N", "R") or not fw.can_allocate


def _expected(fw: Firmware, kind: str, value: int | str, k37: int) -> str:
    """The text the motor prints for ``value`` once stored (6.6), or error00."""
    stored = _memory(fw, k37).normalise(kind, value)
    return format_value(stored)


def _kind(kind: str) -> str:
    if not isinstance(kind, str):
        raise InvalidArgumentError(f"a register kind is a letter such as 'P', not {kind!r}")
    kind = kind.upper()
    if kind not in REGISTER_KINDS:
        raise InvalidArgumentError(f"unknown register {kind!r} (one of {' '.join(REGISTER_KINDS)}; "
                         "K parameters: read_param / write_param)")
    return kind


def read_register(session: Session, motor: int, kind: str, index: int) -> Op[int | str]:
    """``P15.1`` -> ``P15.1=100`` (6.6): an int, or the text of a V string/state."""
    kind = _kind(kind)
    index = args.integer("index", index)
    fw = yield from firmware(session, motor)
    _check_index(fw, kind, index)
    name = register_name(kind, index, motor)
    line = yield from _write_then_read(session, motor, None, name,
                                       _surely_there(fw, kind, index))
    value = (line.value or "").strip()
    if kind == "V" and len(value) >= 2 and value[0] == value[-1] == '"':
        return value[1:-1]
    return parse_int_reply(line, name.split(".")[0], motor)


def write_register(session: Session, motor: int, kind: str, index: int,
                   value: int | str) -> Op[None]:
    """``P15.1=100`` then read back; error00 before sending or when not applied."""
    kind = _kind(kind)
    index = args.integer("index", index)
    if not isinstance(value, str):
        value = args.integer("value", value)
    fw = yield from firmware(session, motor)
    _check_index(fw, kind, index)
    k37 = yield from param(session, motor, 37, cached=True)
    expected = _expected(fw, kind, value, k37)
    name = register_name(kind, index, motor)
    text = f'"{value}"' if isinstance(value, str) else str(int(value))
    line = yield from _write_then_read(session, motor, f"{name}={text}", name,
                                       _surely_there(fw, kind, index))
    got = (line.value or "").strip()
    if kind == "V" and expected.startswith('"'):
        same = got.lower() == expected.lower()  # state names print in canonical case
    else:
        same = got == expected
    if not same:
        if kind != "V":
            line.int_value()      # a read-back that is no number is garbled: ProtocolError
        raise OutOfRangeError(f"{name}={text} was not applied: the motor holds {got!r}")


def _write_then_read(session: Session, motor: int, assignment: str | None,
                     name: str, surely: bool = True) -> Op[Received]:
    """An assignment (or nothing), the query of the same name and a ``?96`` fence: the
    query's reply is the readback.  A memory number the motor does not have answers
    error00 (K23 16) or nothing; both raise :class:`OutOfRangeError`.  When the fence
    is answered and the query is not, the reply was lost on the line
    (:class:`CoolMuscleTimeout`) if the memory is ``surely`` there; else the query is
    asked once more to tell a lost reply from a memory the motor does not have."""
    short = name.split(".")[0]
    lines = (assignment, name) if assignment is not None else (name,)
    answer = yield from fenced(session, motor, lines)
    for line in answer[:-1]:
        if line.name == short and line.motor == motor:
            return line
    if not surely:
        again = yield from fenced(session, motor, (name,))
        if not any(line.name == short and line.motor == motor for line in again[:-1]):
            raise OutOfRangeError(f"{name}: no such register on the motor (no reply to "
                                  f"{name})")
    raise CoolMuscleTimeout(f"no reply to {name}, though the ?96.{motor} after it was "
                            "answered: the reply was lost on the line")


def write_param(session: Session, motor: int, k: int, value: int) -> Op[None]:
    """``K#.n=v`` (ch. 3), validated against the firmware's table 6.1 and read back."""
    k, value = args.integer("k", k), args.integer("value", value)
    if k == 20:
        raise InvalidArgumentError("K20 changes the baud rate of this very line (ch. 3 K20): "
                         "send it with send() and reopen the port at the new rate")
    fw = yield from firmware(session, motor)
    try:
        spec = fw.spec(k)
    except KeyError:
        raise OutOfRangeError(f"K{k} does not exist (K20..K89)") from None
    if spec.reserved and value != spec.default:
        raise OutOfRangeError(f"K{k} is not defined on {fw.name}; it only reads {spec.default}")
    spec.check(value)
    line = yield from _write_then_read(session, motor, f"K{k}.{motor}={value}", f"K{k}.{motor}")
    got = parse_int_reply(line, f"K{k}", motor)
    session.cache(motor).params[k] = got
    if got != value:
        raise OutOfRangeError(f"K{k}.{motor}={value} was not applied: the motor holds {got}")


def read_param(session: Session, motor: int, k: int) -> Op[int]:
    """``K#.n`` (ch. 3): a K number the firmware's table 6.1 has, else refused unsent."""
    k = args.integer("k", k)
    fw = yield from firmware(session, motor)
    try:
        fw.spec(k)
    except KeyError:
        raise OutOfRangeError(f"K{k} does not exist (K20..K89)") from None
    return (yield from param(session, motor, k))


def bank_number(session: Session, motor: int, number: int, ladder: bool = False) -> Op[int]:
    """A program (``B``) or ladder (``L``) bank number of the firmware (2.2.2, 2.2.3)."""
    number = args.integer("bank number", number)
    fw = yield from firmware(session, motor)
    top = fw.ladder_banks if ladder else fw.program_banks
    if not 1 <= number <= top:
        kind = "ladder" if ladder else "program"
        raise OutOfRangeError(f"{kind} bank {number} does not exist (1..{top})")
    return number


def move_lines(fw: Firmware, motor: int, k37: int, *, position: int | None = None,
               relative: bool = False, speed: int | None = None,
               accel: int | None = None, torque: int | None = None) -> list[str]:
    """Direct-mode data lines for a move (2.1.1), each value checked (6.2)."""
    position = args.optional_integer("position", position)
    speed = args.optional_integer("speed", speed)
    accel = args.optional_integer("accel", accel)
    torque = args.optional_integer("torque", torque)
    mem = _memory(fw, k37)
    lines: list[str] = []
    for kind, value in (("S", speed), ("A", accel), ("M", torque)):
        if value is not None:
            mem.normalise(kind, value)
            lines.append(f"{kind}.{motor}={int(value)}")
    if position is not None:
        if relative:
            if abs(position) > _max_position(mem):
                raise OutOfRangeError(f"a move by {position} pulses is out of range")
            op = "+=" if position >= 0 else "-="
            lines.append(f"P.{motor}{op}{abs(int(position))}")
        else:
            mem.normalise("P", position)
            lines.append(f"P.{motor}={int(position)}")
    return lines


def _max_position(mem: Memory) -> int:
    return resolution(mem.k37).max_position


def motion(session: Session, motor: int, lines: list[str]) -> Op[Ux]:
    """Send motion lines, then ``?99``: the status right after the command."""
    answer = yield from fenced(session, motor, tuple(lines), status=True)
    return Ux(answer[-1].int_value())


def move(session: Session, motor: int, position: int, *, relative: bool = False,
         speed: int | None = None, accel: int | None = None,
         torque: int | None = None) -> Op[Ux]:
    """Move to (or by) ``position`` pulses: data lines, ``^.n``, ``?99.n`` (2.1, 2.1.2)."""
    position = args.integer("distance" if relative else "position", position)
    speed, accel = args.optional_integer("speed", speed), args.optional_integer("accel", accel)
    torque = args.optional_integer("torque", torque)
    fw = yield from firmware(session, motor)
    k37 = yield from param(session, motor, 37, cached=True)
    lines = move_lines(fw, motor, k37, position=position, relative=relative, speed=speed,
                       accel=accel, torque=torque)
    return (yield from motion(session, motor, [*lines, f"^.{motor}"]))


def run_continuous(session: Session, motor: int, speed: int,
                   accel: int | None = None) -> Op[Ux]:
    """Continuous rotation: ``P.n=1000000000``; the sign of S is the direction (2.1.1)."""
    speed, accel = args.integer("speed", speed), args.optional_integer("accel", accel)
    fw = yield from firmware(session, motor)
    k37 = yield from param(session, motor, 37, cached=True)
    lines = move_lines(fw, motor, k37, speed=speed, accel=accel)
    return (yield from motion(session, motor, [*lines, f"P.{motor}=1000000000",
                                               f"^.{motor}"]))


def set_output(session: Session, motor: int, number: int, on: bool) -> Op[None]:
    """``O#.n`` / ``F#.n`` (2.1.2; the output's K34 digit must be 3, general use)."""
    number, on = args.integer("output number", number), args.flag("on", on)
    fw = yield from firmware(session, motor)
    if not 1 <= number <= fw.outputs:
        raise OutOfRangeError(f"output {number} does not exist (1..{fw.outputs})")
    yield from fenced(session, motor, (f"{'O' if on else 'F'}{number}.{motor}",))


def output(session: Session, motor: int, number: int) -> Op[bool]:
    """``?5#.n`` -> ``OUT#.n=0|1`` (6.6 ?51..?54)."""
    number = args.integer("output number", number)
    fw = yield from firmware(session, motor)
    if not 1 <= number <= fw.outputs:
        raise OutOfRangeError(f"output {number} does not exist (1..{fw.outputs})")
    line = yield from query(session, motor, f"?{50 + number}.{motor}", f"OUT{number}")
    return parse_int_reply(line, f"OUT{number}", motor) != 0
