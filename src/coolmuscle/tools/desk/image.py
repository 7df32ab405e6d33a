"""A motor as a backup holds it: K parameters, data registers, banks (docs/real-motor.md).

:class:`MotorImage` is one motor ID read from a live line (:mod:`.reading`), a backup
file (:mod:`.backupfile`) or the factory state; :class:`ChainImage` is every motor of a
chain.  Values are kept as the motor prints them (6.6), so that a restore writes back
exactly what was read and a comparison is a comparison of the motor's own answers:

* ``params``: K number -> value, the numbers the firmware defines (``?90``; ch. 3);
* ``allocation``: how many P, N, R memories the motor has (2.1.2, R type), ``None``
  when not known (a backup file that does not say);
* ``data``: register name -> value text, in the order a restore writes them: the P, N,
  R memories, S, A, M, T, V,
  ``H0`` where the motor answers it (5.6.7), then the direct-mode data ``P S A M``
  (6.6 ``?.n``; named without a number);
* ``banks``: ``B1``/``L2`` -> the bank's lines as ``?1000`` lists them (an empty bank
  that exists has no lines).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

from ...client.replies import Version, parse_version
from ...errors import ProtocolError
from ...motor.state.catalogue import KParameter, k_parameter
from ...motor.state.firmware import Firmware, get_firmware

__all__ = ["MotorImage", "ChainImage", "split_items", "MEMORY_KINDS", "DIRECT_KINDS",
           "LINE_PARAMS", "bank_label"]

#: The data registers with memory numbers, in the order they are written (2.1.2: the
#: allocation before P, N, R; 6.2).
MEMORY_KINDS = ("P", "N", "R", "S", "A", "M", "T", "V")
#: The direct-mode data ``?.n`` prints (2.1).
DIRECT_KINDS = ("P", "S", "A", "M")
#: K parameters that change how the host talks to the motors: written last (K20 the
#: rate, ch. 3; K82 the parity; K81 COM0 to Modbus RTU, 5.6).
LINE_PARAMS = (82, 20, 81)


def bank_label(ladder: bool, number: int) -> str:
    return f"{'L' if ladder else 'B'}{number}"


@dataclass(frozen=True)
class MotorImage:
    """One motor: its ``?85`` title, K parameters, data and banks (module docstring)."""

    motor: int
    title: str
    params: Mapping[int, int] = field(default_factory=dict)
    data: Mapping[str, str] = field(default_factory=dict)
    banks: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    allocation: Mapping[str, int] | None = None

    @property
    def version(self) -> Version:
        return parse_version(self.title)

    @property
    def firmware(self) -> str:
        """``cm2``, ``rt3`` or ``cm1``, as the title tells (6.6 ?85)."""
        return self.version.profile()

    @property
    def profile(self) -> Firmware:
        """The firmware profile with this motor's type letter (R: N, R and allocation)."""
        letter = self.version.motor_type.upper()
        fw = get_firmware(self.firmware)
        return fw.with_(motor_type=letter) if letter in ("C", "P", "R") else fw

    def k(self, number: int) -> KParameter:
        """K``number`` of this motor's firmware (meaning, range, factory value)."""
        return k_parameter(self.firmware, number)

    def counted_allocation(self) -> dict[str, int]:
        """How many P, N, R memories the data holds (2.1.2)."""
        counts = {kind: 0 for kind in ("P", "N", "R")}
        for name in self.data:
            kind, number = name[0], name[1:]
            if kind in counts and number.isdigit():
                counts[kind] = max(counts[kind], int(number))
        return counts

    def relabel(self, motor: int) -> MotorImage:
        """The same image as motor ID ``motor`` (its title says that ID)."""
        title = self.title
        try:
            version = parse_version(title)
            title = title.replace(f"ID{version.motor} :", f"ID{motor} :", 1)
        except ProtocolError:
            pass
        return replace(self, motor=motor, title=title)


@dataclass(frozen=True)
class ChainImage:
    """Every motor of a chain, in ID order, and where they were read."""

    motors: tuple[MotorImage, ...]
    source: str = ""
    baud: int | None = None
    taken: str = ""

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(m.motor for m in self.motors)

    def motor(self, motor_id: int) -> MotorImage:
        found = next((m for m in self.motors if m.motor == motor_id), None)
        if found is None:
            raise LookupError(f"ID{motor_id} is not in {self.source or 'the image'}")
        return found


def split_items(line: str) -> list[tuple[str, int, str]]:
    """A listing line of 6.6 (``?90``, ``?P``, ``?V``, ``?.n``): ``(name, motor, value)``
    for each ``NAME.n=VALUE`` item; items are separated by a comma outside quotes
    (a V string may hold a comma, 2.2.1)."""
    items: list[tuple[str, int, str]] = []
    for piece in _pieces(line):
        name, dot, rest = piece.partition(".")
        motor, eq, value = rest.partition("=")
        if not (dot and eq and name and motor.isdigit()):
            raise ProtocolError(f"garbled listing item {piece!r} in {line!r}")
        items.append((name, int(motor), value))
    return items


def _pieces(line: str) -> list[str]:
    pieces: list[str] = []
    current: list[str] = []
    quoted = False
    for ch in line:
        if ch == '"':
            quoted = not quoted
        if ch == "," and not quoted:
            pieces.append("".join(current).strip())
            current = []
        else:
            current.append(ch)
    pieces.append("".join(current).strip())
    return [p for p in pieces if p]
