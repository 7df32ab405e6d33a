"""The Modbus register map of one motor, over the device API (cml-users-guide.txt 5.6.7).

This module owns *where* each value lives and how it becomes words:

* FC03 (read) and FC16 (write) address "motor information and data" at
  K78-relative addresses (5.6.7 tables "Function Code 03" and "16").  Every value is
  a long: two words (5.6.7 "*... all the data are Long type (2 Word)"), whose order
  K85 chooses (5.6.5: big endian = high word first; little endian = low word first;
  the bytes of a word are always high byte first, as Modbus sends words).
* FC04 reads one word per motor: inputs of ID1–ID15 at K78+0..14, outputs at
  K78+16..30, status at K78+32..46 (5.6.7 "Function Code 04").

Values are read through :class:`coolmuscle.device.api.Device` (``snapshot``,
``get_register``, ``register_value``, ``get_param``) and written as the CML
assignment the motor itself executes (``P0.1=12345``), so range checks, error
reports and side effects are the motor's.  Nothing here knows frames or CRCs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ...device.api import Device, MotorSnapshot

#: Words per value (5.6.7: "all the data are Long type (2 Word)").
LONG = 2

#: K78-relative addresses of the two CML command inputs (5.6.7 FC16 table).
CML_COMMAND = 100          # "Send CMLCommand": ASCII, the value after '=' in binary
CML_COMMAND_MODBUS = 102   # "Send CMLCommand (For Modbus)": all ASCII

#: FC04 blocks (5.6.7 FC04 table): K78-relative start of each block of 15 words.
FC04_INPUTS, FC04_OUTPUTS, FC04_STATUS = 0, 16, 32
FC04_MOTORS = 15

#: Largest register counts a request may name (a PDU holds at most 253 bytes).
MAX_READ = 125
MAX_WRITE = 123

Live = Callable[["MotorSnapshot"], int]


@dataclass(frozen=True, slots=True)
class Cell:
    """One long value of the FC03/FC16 map.

    ``live`` reads it from a snapshot; otherwise ``kind``/``index`` name the data
    register (``"P", 0``), the K parameter (``"K", 20``) or the V register.
    ``writable`` cells are the FC16 table's rows; their CML name is ``name``.
    """

    offset: int
    name: str
    kind: str = ""
    index: int = 0
    live: Live | None = None
    writable: bool = False


def _analog_output(snap: MotorSnapshot) -> int:
    # K78+54 "Analog Output" has no CML query; the motor model publishes it in
    # ``extra`` when it models the analog output (docs/fidelity.md "Modbus").
    return int(snap.extra.get("analog_output", 0))


def _build_cells() -> dict[int, Cell]:
    cells: list[Cell] = [
        Cell(0, "Pe", live=lambda s: s.position_error),     # ?95
        Cell(2, "Px", live=lambda s: s.position),           # ?96
        Cell(4, "Sx", live=lambda s: s.speed),              # ?97
        Cell(6, "Ix", live=lambda s: s.torque),             # ?98
        Cell(8, "Ux", live=lambda s: s.status),             # ?99
        Cell(52, "ADIN", live=lambda s: s.analog),          # ?74
        Cell(54, "AOUT", live=_analog_output),
        Cell(56, "IN", live=lambda s: s.inputs),            # ?70
        Cell(58, "OUT", live=lambda s: s.outputs),          # ?50
        Cell(686, "Temp", live=lambda s: s.temperature),    # ?71
        Cell(670, "H0", "H", 0, writable=True),
    ]
    cells += [Cell(10 + 2 * i, f"V{i}", "V", i, writable=True) for i in range(16)]
    cells += [Cell(200 + 2 * i, f"P{i}", "P", i, writable=True) for i in range(201)]
    cells += [Cell(602 + 2 * i, f"S{i}", "S", i, writable=True) for i in range(16)]
    cells += [Cell(634 + 2 * i, f"A{i}", "A", i, writable=True) for i in range(9)]
    cells += [Cell(652 + 2 * i, f"M{i}", "M", i, writable=True) for i in range(9)]
    cells += [Cell(696 + 2 * (i - 1), f"T{i}", "T", i, writable=True) for i in range(1, 9)]
    cells += [Cell(752 + 2 * (k - 20), f"K{k}", "K", k, writable=True) for k in range(20, 90)]
    return {c.offset: c for c in cells}


#: K78-relative offset of a value's first word -> the value.
CELLS: dict[int, Cell] = _build_cells()


class RegisterError(LookupError):
    """A register address or range the map does not have (exception 02)."""


def words_of(value: int, little: bool) -> tuple[int, int]:
    """The two words of a signed long, in K85 order (5.6.5)."""
    value &= 0xFFFFFFFF
    high, low = value >> 16, value & 0xFFFF
    return (low, high) if little else (high, low)


def long_of(first: int, second: int, little: bool) -> int:
    """The signed long two words carry, in K85 order (5.6.5)."""
    high, low = (second, first) if little else (first, second)
    value = (high << 16) | low
    return value - 0x1_0000_0000 if value & 0x8000_0000 else value


class MotorMap:
    """The FC03/FC04/FC16 registers of one motor of ``device`` (5.6.7).

    ``base`` is the motor's K78, ``little`` its K85 endian for COM0; both are read
    by the caller once per request.  A snapshot is taken at most once per request.
    """

    def __init__(self, device: Device, motor: int, base: int, little: bool) -> None:
        self.device = device
        self.motor = motor
        self.base = base
        self.little = little
        self._snap: MotorSnapshot | None = None

    def _snapshot(self) -> MotorSnapshot:
        if self._snap is None:
            self._snap = self.device.snapshot(self.motor)
        return self._snap

    def value(self, cell: Cell) -> int:
        """The current value of ``cell`` (a long)."""
        if cell.live is not None:
            return int(cell.live(self._snapshot()))
        if cell.kind == "K":
            return self.device.get_param(self.motor, cell.index)
        return self.device.register_value(self.motor, cell.kind, cell.index)

    # -- FC03 -----------------------------------------------------------------
    def read_holding(self, address: int, count: int) -> list[int]:
        """Words ``address .. address+count-1``; :class:`RegisterError` on a gap.

        A read may start or end in the middle of a value (mbpoll reads single
        words); every word it covers must belong to a value of the table.
        """
        if not 1 <= count <= MAX_READ:
            raise RegisterError(f"count {count} (1..{MAX_READ})")
        rel = address - self.base
        words: list[int] = []
        cell_words: tuple[int, int] = (0, 0)
        current = -1
        for offset in range(rel, rel + count):
            start = offset - (offset & 1)
            if start != current:
                cell = CELLS.get(start) if offset >= 0 else None
                if cell is None:
                    raise RegisterError(f"no value at K78+{offset}")
                try:
                    cell_words = words_of(self.value(cell), self.little)
                except (LookupError, ValueError) as exc:   # memory number not allocated
                    raise RegisterError(f"{cell.name}: {exc}") from None
                current = start
            words.append(cell_words[offset & 1])
        return words

    # -- FC04 -----------------------------------------------------------------
    def read_input(self, address: int, count: int) -> list[int]:
        """FC04 words: input, output and status words of ID1–ID15 (absent IDs read 0)."""
        if not 1 <= count <= MAX_READ:
            raise RegisterError(f"count {count} (1..{MAX_READ})")
        rel = address - self.base
        present = set(self.device.motor_ids)
        snaps: dict[int, MotorSnapshot] = {}
        words: list[int] = []
        for offset in range(rel, rel + count):
            block, slot = divmod(offset, 16) if offset >= 0 else (-1, 0)
            if block not in (0, 1, 2) or slot >= FC04_MOTORS:
                raise RegisterError(f"no FC04 word at K78+{offset}")
            motor = slot + 1
            if motor not in present:
                words.append(0)
                continue
            snap = snaps.get(motor)
            if snap is None:
                snap = snaps[motor] = self.device.snapshot(motor)
            word = (snap.inputs, snap.outputs, snap.status)[block]
            words.append(int(word) & 0xFFFF)
        return words

    # -- FC16 -----------------------------------------------------------------
    def writable_cells(self, address: int, count: int) -> list[Cell]:
        """The values an FC16 data write covers; :class:`RegisterError` if it cannot.

        A data write starts on a value's first word and covers whole values
        (5.6.7 FC16: "The data byte number is 2Word"), all of them FC16 rows.
        """
        rel = address - self.base
        if count < LONG or count % LONG or count > MAX_WRITE or rel < 0 or rel % LONG:
            raise RegisterError(f"write of {count} words at K78+{rel}")
        cells = []
        for offset in range(rel, rel + count, LONG):
            cell = CELLS.get(offset)
            if cell is None or not cell.writable:
                raise RegisterError(f"K78+{offset} cannot be written")
            try:            # 5.6.8 02 "The specified data address does not exist"
                self.value(cell)
            except (LookupError, ValueError) as exc:   # a memory number not allocated
                raise RegisterError(f"{cell.name}: {exc}") from None
            cells.append(cell)
        return cells

    def assignment(self, cell: Cell, value: int) -> str:
        """The CML line an FC16 data write executes: ``P0.1=12345`` (2.1.1, ch. 3)."""
        return f"{cell.name}.{self.motor}={value}"
