"""Query replies, formatted exactly as cml-users-guide.txt 6.6 shows them.

``?96.1`` -> ``Px.1=10000``; ``?50.1`` -> ``OUT.1=03``; ``P15.1`` -> ``P15.1=...``;
``?A.1`` -> all A data, four to a line, separated by ", " (6.6 "?A").
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from ...cml import ast
from ..state.memory import VNumber, VState, VString
from ..status import io_word_hex

if TYPE_CHECKING:
    from ..core import MotorCore

#: Memory kinds listed by ?999, in the order 6.6 gives ("All data of P, S, A, T, M, N, R, V").
ALL_DATA_ORDER = ("P", "S", "A", "T", "M", "N", "R", "V")
PER_LINE = 4


def register_name(kind: str, index: int | None, motor_id: int) -> str:
    """``P15.1``, ``P.1`` (direct data), ``K23.1``."""
    return f"{kind}{'' if index is None else index}.{motor_id}"


def format_value(value: object) -> str:
    """A register value as it is printed: V strings and states in double quotes."""
    if isinstance(value, VString):
        return f'"{value.text}"'
    if isinstance(value, VState):
        return f'"{value.name}"'
    if isinstance(value, VNumber):
        return str(value.value)
    return str(value)


def register_reply(motor: MotorCore, reg: ast.Reg) -> str:
    """Reply to a register named alone in direct mode (6.6 "P1~200", "S1~15", ...)."""
    if reg.kind == "K":
        value: object = motor.k(reg.number)
    else:
        value = motor.memory.get(reg.kind, reg.number)
    return f"{register_name(reg.kind, reg.index, motor.id)}={format_value(value)}"


def display_reply(motor: MotorCore, reg: ast.Reg) -> str:
    """A register named alone on a bank line (2.2.1, 2.2.2 "V": "When this command is
    used alone, it displays the specified variable data"): a V holding a state shows
    the state's value now (``V4.1=10000`` for ``V4.1="Px"``), as ``V5.1=V4.1`` reads
    it; everything else as :func:`register_reply`."""
    if reg.kind == "V":
        value = motor.memory.get("V", reg.number)
        if isinstance(value, VState):
            return f"{register_name('V', reg.index, motor.id)}={motor.state_value(value.name)}"
    return register_reply(motor, reg)


def group_lines(items: list[str], per_line: int = PER_LINE) -> list[str]:
    """Join items four to a line with ", " (6.6 ?90, ?A ...)."""
    return [", ".join(items[i:i + per_line]) for i in range(0, len(items), per_line)]


def data_listing(motor: MotorCore, kind: str) -> list[str]:
    """?A, ?S, ?M, ?T, ?V, ?P, ?N, ?R: memory numbers 1..N of one kind."""
    items = []
    for index, value in motor.memory.items(kind):
        if index == 0:
            continue
        items.append(f"{kind}{index}.{motor.id}={format_value(value)}")
    return group_lines(items)


def direct_data(motor: MotorCore) -> list[str]:
    """``?.n``: the direct-mode data, in the 2.1 operation example's form."""
    m = motor.id
    get = motor.memory.get
    return [f"P.{m}={format_value(get('P', 0))}, S.{m}={format_value(get('S', 0))}, "
            f"A.{m}={format_value(get('A', 0))}, M.{m}={format_value(get('M', 0))}"]


def _live(motor: MotorCore) -> dict[int, Callable[[], str]]:
    m = motor.id
    return {
        50: lambda: f"OUT.{m}={io_word_hex(motor.io.output_word(), motor.io.output_count)}",
        70: lambda: f"IN.{m}={io_word_hex(motor.io.input_word(), motor.io.input_count)}",
        71: lambda: f"Temp.{m}={motor.temperature}",
        72: lambda: f"VSEN.{m}={motor.voltage}",
        74: lambda: f"ADI0.{m}={motor.analog}",
        76: lambda: f"Ecnt.{m}={motor.encoder_count}",
        85: lambda: motor.firmware.version_title(m),
        95: lambda: f"Pe.{m}={round(motor.axis.position_error())}",
        96: lambda: f"Px.{m}={motor.position()}",
        97: lambda: f"Sx.{m}={motor.speed_units()}",
        98: lambda: f"Ix.{m}={motor.torque()}",
        99: lambda: f"Ux.{m}={motor.status}",
    }


def query_lines(motor: MotorCore, query: ast.Query) -> list[str] | None:
    """Reply lines for ``query``; ``None`` when the motor does not know it (silence)."""
    m = motor.id
    if query.letter is None and query.number is None:
        return direct_data(motor)
    if query.letter is not None and query.letter != "L":
        if query.letter in ("N", "R") and not motor.firmware.has_interpolation:
            return None
        return data_listing(motor, query.letter)
    number = query.number
    if query.letter is None and number is not None:
        if 51 <= number <= 50 + motor.io.output_count:
            return [f"OUT{number - 50}.{m}={int(motor.io.output_port(number - 50))}"]
        if number == 90:
            return motor.params.format_param_listing(m)
        if number == 999:
            lines: list[str] = []
            for kind in ALL_DATA_ORDER:
                if kind in ("N", "R") and not motor.firmware.has_interpolation:
                    continue
                lines += data_listing(motor, kind)
            return lines
        live = _live(motor).get(number)
        if live is not None:
            return [live()]
    return None
