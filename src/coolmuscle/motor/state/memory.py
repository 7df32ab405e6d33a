"""Data registers of one motor: P S A M T V N R and H0 (CML 2.1.1, 2.2.1, 6.2, 5.6.7).

This module owns register ranges, memory numbers, the V value types, the
``\\P`` / ``\\N`` allocation of 2.1.2 and the serialisable form the store saves.
It does not evaluate V states: a V register bound to ``"Px"`` holds a
:class:`VState` and the motor reads the live value when it is used.

Errors: a value outside its range raises :class:`OutOfRangeError` (error00); a
memory number that does not exist raises :class:`NoSuchRegisterError`, which is
both an ``OutOfRangeError`` (the motor reports error00 ``Out Of Range!!``) and an
``IndexError``.

Compiled (coolmuscle/_accel.py): what the methods check at run time (a kind, a
memory number, a value) is typed ``object``, so a float or a bool reaches the check
and gets the error above instead of the compiled code's ``TypeError`` or a bool taken
as 0 or 1.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal, overload

from ...cml.ast import Frozen
from ...errors import OutOfRangeError
from .firmware import REGISTER_KINDS, Firmware
from .units import CONTINUOUS, resolution, valid_k37

#: 6.2 V "Max 1000000000"; also the N and R limits (2.2.1).
LIMIT_1E9 = 1_000_000_000
#: 2.2.1 V: "up to 4 digit numbers like 4 characters".
MAX_V_STRING = 4
#: H0 servo stiffness (5.6.7): the manual gives no range; 0..32767 chosen.
H_RANGE = (0, 32767)

#: Plain ranges (6.2, 2.2.1).  P, A and V are checked by their own rules.
_RANGES: dict[str, tuple[int, int]] = {
    "S": (-32767, 32767), "A": (1, 32767), "M": (0, 100), "T": (0, 32767),
    "N": (-LIMIT_1E9, LIMIT_1E9), "R": (-LIMIT_1E9, LIMIT_1E9), "H": H_RANGE,
}

#: Factory values (not given by the manuals; docs/fidelity.md).
_DEFAULTS: dict[str, int] = {"P": 0, "S": 10, "A": 100, "M": 100, "T": 0,
                             "N": 0, "R": 0, "H": 0}


class NoSuchRegisterError(OutOfRangeError, IndexError):
    """A memory number the register does not have (reported as error00)."""


# -- V values ------------------------------------------------------------------

@dataclass(frozen=True, slots=True)
class VNumber(Frozen):
    """A V register holding a number (6.2 V "1) use as a number")."""

    value: int


@dataclass(frozen=True, slots=True)
class VString(Frozen):
    """A V register holding up to 4 characters (6.2 V "2) use as character")."""

    text: str


@dataclass(frozen=True, slots=True)
class VState(Frozen):
    """A V register bound to a live motor state (6.2 V "3) internal state").

    ``name`` is canonical (``"Px"``, ``"ADIN"``, ``"CT"`` ...); the motor
    resolves it each time the register is read (or, for ``Dx``, written).
    """

    name: str

    @property
    def write_only(self) -> bool:
        """RT3 ``Dx`` is written (target position), never read."""
        return self.name == "Dx"


VValue = VNumber | VString | VState
#: The registers that hold numbers (every kind but V), as the type checker names them.
NumericKind = Literal["P", "S", "A", "M", "T", "N", "R", "H"]

#: Every spelling in the manuals, upper-cased, to the canonical state name.
#: CML 6.2 / 2.2.1: Px Sx Ix Ux Pe ADIN (formerly AIN) PT ST CT; CML 5.4.3: Ecnt;
#: RT3 1.3: Pt, AIN4, Dx, St, Fx, Cx.
STATE_ALIASES: dict[str, str] = {
    "PX": "Px", "SX": "Sx", "IX": "Ix", "UX": "Ux", "PE": "Pe",
    "ADIN": "ADIN", "AIN": "ADIN", "AIN4": "ADIN",
    "PT": "PT", "ST": "ST", "CT": "CT", "ECNT": "CT",
    "DX": "Dx", "FX": "Fx", "CX": "Cx",
}


def state_name(text: str, known: frozenset[str] | None = None) -> str | None:
    """Canonical state for ``text`` (any case, any alias), or ``None``.

    With ``known`` (a firmware's :attr:`~Firmware.states`) a state that firmware
    does not know is not a state: it is just characters.
    """
    name = STATE_ALIASES.get(text.strip().upper())
    if name is None or (known is not None and name not in known):
        return None
    return name


def parse_v_text(text: str, known: frozenset[str] | None = None) -> VString | VState:
    """The value of ``V#="text"``: a state if ``text`` names one, else a string."""
    name = state_name(text, known)
    if name is not None:
        return VState(name)
    check_v_string(text)
    return VString(text)


def check_v_string(text: str) -> None:
    """1 to 4 printable one-byte characters, no double quote (2.2.1 V, ch. 1)."""
    ok = (1 <= len(text) <= MAX_V_STRING
          and all(" " <= ch <= "~" and ch != '"' for ch in text))
    if not ok:
        raise OutOfRangeError(f"V string {text!r} must be 1-4 one-byte characters")


# -- the registers ---------------------------------------------------------------

class Memory:
    """All data registers of one motor for one firmware profile.

    ``k37`` (the current resolution) bounds P: ``±max position`` of K37, except
    exactly 1000000000, which means continuous rotation (2.1.1 P, ch. 3 K37).
    The motor keeps it current (K37 change listener, :meth:`set_k37`).
    """

    _k37: int

    def __init__(self, firmware: Firmware, *, k37: int = 3) -> None:
        self._firmware = firmware
        self.set_k37(k37)
        self._alloc: dict[str, int] = {}
        self._data: dict[str, list[Any]] = {}
        #: The live cells by kind (index = memory number), read only: the ladder
        #: scanner's fast reads.  The same dict for the life of the memory.
        self.data = self._data
        self.reset()

    # -- shape -----------------------------------------------------------------

    @property
    def firmware(self) -> Firmware:
        """The profile this memory follows."""
        return self._firmware

    @property
    def k37(self) -> int:
        """The K37 value P is checked against (:meth:`set_k37` changes it)."""
        return self._k37

    def set_k37(self, value: int) -> None:
        """Check P against K37 = ``value`` from now on; :class:`OutOfRangeError` if it is
        not a resolution.  A method, not a property setter: compiled, mypyc 1.19's setter
        wrapper loses an exception raised in the setter (a ``SystemError`` follows)."""
        if not valid_k37(value):
            raise OutOfRangeError(f"K37={value} is not a resolution")
        self._k37 = value

    def _factory_allocation(self) -> dict[str, int]:
        regs = self._firmware.registers
        return {"P": regs.p, "N": regs.n, "R": regs.r}

    def limit(self, kind: str) -> int:
        """Highest memory number of ``kind`` (index 0 is the direct-mode data)."""
        kind = _kind(kind)
        if kind in self._alloc:
            return self._alloc[kind]
        return self._firmware.registers.limit(kind)

    @property
    def allocation(self) -> dict[str, int]:
        """Current P / N / R counts (2.1.2)."""
        return dict(self._alloc)

    # -- access ----------------------------------------------------------------

    @overload
    def get(self, kind: NumericKind, index: int) -> int: ...

    @overload
    def get(self, kind: Literal["V"], index: int) -> VValue: ...

    @overload
    def get(self, kind: str, index: int) -> int | VValue: ...

    def get(self, kind: object, index: object) -> int | VValue:
        """The value of ``kind`` memory ``index`` (a :data:`VValue` for V)."""
        return self._cell(kind, index)

    def _cell(self, kind: object, index: object) -> int | VValue:
        kind = _kind(kind)
        value: int | VValue = self._data[kind][self._check_index(kind, index)]
        return value

    def number(self, kind: str, index: object) -> int:
        """The value of a numeric memory (``S``, ``A``, ``P``, ``M``, ``T`` ...; not V)."""
        cells = self._data.get(kind)        # fast path: a canonical kind, a valid index
        if cells is not None and type(index) is int and 0 <= index < len(cells):
            found = cells[index]
            if type(found) is int:
                return found
        value = self._cell(kind, index)
        if not isinstance(value, int):
            raise TypeError(f"{kind}{index} holds {value!r}, not a number")
        return value

    def cells(self, kind: str) -> list[Any]:
        """The live cells of ``kind`` (index = memory number), for fast reads by the
        ladder scanner; read only.  The list is replaced when the allocation changes."""
        return self._data[kind]

    def set_v_number(self, index: int, value: object) -> None:
        """``V#=value`` with a number, as :meth:`set` checks it (fast path for ladder scans)."""
        cells = self._data["V"]
        if not (type(value) is int and -LIMIT_1E9 <= value <= LIMIT_1E9):
            raise OutOfRangeError(f"V={value!r} is out of range")
        if not 0 <= index < len(cells):
            raise NoSuchRegisterError(f"V{index} does not exist (V0..V{len(cells) - 1})")
        cells[index] = VNumber(value)

    def set(self, kind: object, index: object, value: object) -> None:
        """Store ``value``; nothing changes if it is refused.

        V accepts an int, a :data:`VValue`, or ``str`` (the text between the
        quotes of ``V#="..."``).  A takes the absolute value (6.2 A).
        """
        kind = _kind(kind)
        self._data[kind][self._check_index(kind, index)] = self.normalise(kind, value)

    def normalise(self, kind: object, value: object) -> int | VValue:
        """The value as it would be stored, or :class:`OutOfRangeError`."""
        kind = _kind(kind)
        if kind == "V":
            return self._v_value(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise OutOfRangeError(f"{kind} takes an integer, not {value!r}")
        if kind == "P":
            return self._p_value(value)
        if kind == "A":
            value = abs(value)
        lo, hi = _RANGES[kind]
        if not lo <= value <= hi:
            raise OutOfRangeError(f"{kind}={value} is out of range {lo}..{hi}")
        return value

    def _p_value(self, value: int) -> int:
        if value == CONTINUOUS:
            return value
        top = resolution(self._k37).max_position
        if not -top <= value <= top:
            raise OutOfRangeError(f"P={value} is beyond ±{top} (K37={self._k37})")
        return value

    def _v_value(self, value: object) -> VValue:
        if isinstance(value, (VNumber, VString, VState)):
            if isinstance(value, VNumber):
                return self._v_value(value.value)
            if isinstance(value, VString):
                check_v_string(value.text)
            elif value.name not in self._firmware.states:
                raise OutOfRangeError(f"state {value.name!r} is unknown to this firmware")
            return value
        if isinstance(value, str):
            return parse_v_text(value, self._firmware.states)
        if isinstance(value, bool) or not isinstance(value, int):
            raise OutOfRangeError(f"V takes a number or text, not {value!r}")
        if not -LIMIT_1E9 <= value <= LIMIT_1E9:
            raise OutOfRangeError(f"V={value} is out of range")
        return VNumber(value)

    def _check_index(self, kind: str, index: object) -> int:
        top = len(self._data[kind]) - 1   # the cells are sized to limit(kind) + 1
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index <= top:
            raise NoSuchRegisterError(f"{kind}{index} does not exist ({kind}0..{kind}{top})")
        return index

    def items(self, kind: object) -> list[tuple[int, int | VValue]]:
        """``(index, value)`` for every memory number of ``kind``, from 0."""
        return list(enumerate(self._data[_kind(kind)]))

    # -- allocation (2.1.2) ----------------------------------------------------

    def allocate(self, kind: object, count: object) -> None:
        """``\\P n`` or ``\\N n``: divide the 600 P+N+R memories (R type only).

        P is served first, then N; R gets the rest.  ``\\P`` keeps N if it still
        fits (else N shrinks to what is left); ``\\N`` must fit beside P.
        Memories that remain keep their data, memories cut off are lost, new
        ones start at the factory value.  Index 0 (direct mode) always stays.
        """
        kind = _kind(kind)
        pool = self._firmware.pnr_pool
        if pool is None or not self._firmware.can_allocate:
            raise OutOfRangeError("allocation is only available on the R (interpolation) type")
        if kind not in ("P", "N"):
            raise OutOfRangeError(f"\\{kind} is not an allocation (only \\P and \\N)")
        if isinstance(count, bool) or not isinstance(count, int):
            raise OutOfRangeError(f"allocation count {count!r} is not a number")
        p, n = self._alloc["P"], self._alloc["N"]
        if kind == "P":
            if not 0 <= count <= pool:
                raise OutOfRangeError(f"\\P{count}: 0..{pool}")
            p, n = count, min(n, pool - count)
        else:
            if not 0 <= count <= pool - p:
                raise OutOfRangeError(f"\\N{count}: 0..{pool - p} beside P{p}")
            n = count
        self._resize({"P": p, "N": n, "R": pool - p - n})

    def _resize(self, alloc: dict[str, int]) -> None:
        for kind, count in alloc.items():
            cells = self._data[kind][:count + 1]
            cells += [_DEFAULTS[kind]] * (count + 1 - len(cells))
            self._data[kind] = cells
        self._alloc = dict(alloc)

    # -- whole memory ----------------------------------------------------------

    def reset(self) -> None:
        """Factory state: default values, factory allocation."""
        self._alloc = self._factory_allocation()
        self._data.clear()
        for kind in REGISTER_KINDS:
            size = self.limit(kind) + 1
            fill: Any = VNumber(0) if kind == "V" else _DEFAULTS[kind]
            self._data[kind] = [fill] * size

    def to_dict(self) -> dict[str, Any]:
        """JSON-compatible form: ``{"alloc": {...}, "P": [...], "V": [...], ...}``.

        V cells are an int, ``{"s": text}`` or ``{"state": name}``.
        """
        out: dict[str, Any] = {"alloc": dict(self._alloc)}
        for kind in REGISTER_KINDS:
            cells = self._data[kind]
            out[kind] = [_encode_v(c) for c in cells] if kind == "V" else list(cells)
        return out

    @classmethod
    def from_dict(cls, firmware: Firmware, data: Mapping[str, Any], *,
                  k37: int = 3) -> Memory:
        """Rebuild from :meth:`to_dict` output; ``ValueError`` if it does not fit.

        Every value is checked as if it were written now (with ``k37``).
        """
        memory = cls(firmware, k37=k37)
        try:
            memory._load(data)
        except (OutOfRangeError, KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"saved memory does not fit {firmware.name}: {exc}") from exc
        return memory

    def _load(self, data: Mapping[str, Any]) -> None:
        alloc = {k: int(v) for k, v in dict(data["alloc"]).items()}
        if alloc != self._alloc:
            if set(alloc) != {"P", "N", "R"} or not self._firmware.can_allocate:
                raise TypeError(f"allocation {alloc} not possible")
            if sum(alloc.values()) != self._firmware.pnr_pool or min(alloc.values()) < 0:
                raise TypeError(f"allocation {alloc} does not add up")
            self._resize(alloc)
        for kind in REGISTER_KINDS:
            cells = list(data[kind])
            if len(cells) != self.limit(kind) + 1:
                raise TypeError(f"{kind} has {len(cells)} cells")
            decoded = [_decode_v(c) for c in cells] if kind == "V" else cells
            for index, value in enumerate(decoded):
                self.set(kind, index, value)


_CANONICAL_KINDS = frozenset(REGISTER_KINDS)


def _kind(kind: object) -> str:
    if isinstance(kind, str) and kind in _CANONICAL_KINDS:   # fast path (ladder scans)
        return kind
    upper = kind.upper() if isinstance(kind, str) else ""
    if upper not in REGISTER_KINDS:
        raise ValueError(f"unknown register kind {kind!r}")
    return upper


def _encode_v(value: VValue) -> Any:
    if isinstance(value, VNumber):
        return value.value
    if isinstance(value, VString):
        return {"s": value.text}
    return {"state": value.name}


def _decode_v(cell: Any) -> VValue:
    if isinstance(cell, int) and not isinstance(cell, bool):
        return VNumber(cell)
    if isinstance(cell, Mapping) and set(cell) == {"s"}:
        return VString(str(cell["s"]))
    if isinstance(cell, Mapping) and set(cell) == {"state"}:
        return VState(str(cell["state"]))
    raise TypeError(f"bad V cell {cell!r}")


#: V states a bank may write through (cm-banks-rt3.txt 1.3: Dx target position, St target speed).
WRITABLE_STATES = frozenset({"Dx", "ST"})
