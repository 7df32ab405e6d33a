"""The CML syntax tree: frozen dataclasses that the parser returns.

One tree serves direct mode, program banks and ladder banks; what a node *does*
depends on where it runs (cml-users-guide.txt 2.1, 2.2.2, 2.2.3).  For example a
bare ``P1.1`` is a query in direct mode (6.6 "P1~200"), a move in a program bank
(2.2.2 "P") and a display in a ladder bank (4.5.1).  The executor decides.

Conventions
-----------
* ``index``: the memory/bank/output number written after the letter, ``None``
  when omitted (``P.1`` is P0, the direct-mode data, 2.1.1).
* ``motor``: the motor ID written after the dot, ``None`` when omitted.  The
  executor fills in the default (the bank's motor, or the addressed motor).
* Letters are stored upper-case; CML is case-insensitive (1.1).
* Numbers are Python ints (CML is integer-only, 6.7).

Compiled with the hot modules (coolmuscle/_accel.py: the program executor reads the
nodes at every line).  Two things keep the classes the same compiled: every node is a
:class:`Frozen`, and no field's annotation is quoted (``left: Expr``, not ``"Expr"``:
``dataclasses`` would look a quoted name up in ``sys.modules``, where a compiled module
is not yet while its classes are made).
"""

from __future__ import annotations

from dataclasses import Field, dataclass, fields
from typing import Any, ClassVar, Literal


class Frozen:
    """Base of the nodes (and of the V values, motor/state/memory.py): frozen, slotted
    dataclasses, pickled by their field values.

    ``slots=True`` gives a frozen dataclass these two methods, and the sources use its
    own.  Compiled, mypyc keeps its class, not the one ``slots=True`` makes, and its
    default pickling would set the fields through the frozen ``__setattr__``
    (``FrozenInstanceError``); these make the same pickles as the sources.
    """

    __slots__ = ()
    __dataclass_fields__: ClassVar[dict[str, Field[Any]]]

    def __getstate__(self) -> list[object]:
        return [getattr(self, f.name) for f in fields(self)]

    def __setstate__(self, state: list[object]) -> None:
        for f, value in zip(fields(self), state):
            object.__setattr__(self, f.name, value)

# --------------------------------------------------------------------------
# Operands and expressions (6.7 arithmetic, 6.8 logic, 6.9 comparison)
# --------------------------------------------------------------------------

RegisterKind = Literal["P", "S", "A", "M", "T", "V", "N", "R", "K", "H"]
REGISTER_KINDS: tuple[str, ...] = ("P", "S", "A", "M", "T", "V", "N", "R", "K", "H")


@dataclass(frozen=True, slots=True)
class Num(Frozen):
    """An integer literal, e.g. ``10000`` or ``-5000``."""

    value: int


@dataclass(frozen=True, slots=True)
class Str(Frozen):
    """A double-quoted string: up to 4 characters or a state name (2.2.1 "V")."""

    text: str


@dataclass(frozen=True, slots=True)
class Reg(Frozen):
    """A register reference such as ``P2.1``, ``S.1``, ``V3``, ``K23.1``."""

    kind: str
    index: int | None = None
    motor: int | None = None

    @property
    def number(self) -> int:
        """The memory number with an omitted index read as 0 (direct data)."""
        return 0 if self.index is None else self.index


@dataclass(frozen=True, slots=True)
class Input(Frozen):
    """An input reference ``I#.n``: 1 when the input signal is on, else 0."""

    index: int
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class BinOp(Frozen):
    """Arithmetic ``+ - * /`` (integer, division truncates, 6.7)."""

    op: Literal["+", "-", "*", "/"]
    left: Expr
    right: Expr


@dataclass(frozen=True, slots=True)
class Func(Frozen):
    """Math function ``U1``..``U6`` (6.7; cm-banks-rt3.txt 1.5)."""

    name: Literal["U1", "U2", "U3", "U4", "U5", "U6"]
    arg: Expr


@dataclass(frozen=True, slots=True)
class Compare(Frozen):
    """Comparison ``== != > >= < <=`` (6.9)."""

    op: Literal["==", "!=", ">", ">=", "<", "<="]
    left: Expr
    right: Expr


@dataclass(frozen=True, slots=True)
class Logic(Frozen):
    """Logical ``&&`` / ``||`` (6.8)."""

    op: Literal["&&", "||"]
    left: Expr
    right: Expr


@dataclass(frozen=True, slots=True)
class Not(Frozen):
    """Negation ``!!(operand)`` (6.8)."""

    operand: Expr


Expr = Num | Str | Reg | Input | BinOp | Func | Compare | Logic | Not

# --------------------------------------------------------------------------
# Statements
# --------------------------------------------------------------------------

Modifier = Literal["+", "-"] | None


@dataclass(frozen=True, slots=True)
class Assign(Frozen):
    """``target = expr``, ``target += expr``, ``target -= expr`` (2.1.1, 6.2, 6.7).

    Also parameter setting ``K23.1=16`` (ch. 3) and ``H0``.
    """

    target: Reg
    op: Literal["=", "+=", "-="]
    value: Expr


@dataclass(frozen=True, slots=True)
class Ref(Frozen):
    """A register named alone: ``P1.1``, ``P2.1+``, ``S1.1``, ``T1.1``, ``V2.1``, ``R1.1-``.

    Direct mode: a query.  Program bank: P moves (``+`` relative), S/A/M select
    the data used by the next motion, T waits, V displays, N/R select the
    interpolation centre/radius (``-`` picks the minor arc).  Ladder: displays.
    """

    reg: Reg
    modifier: Modifier = None


@dataclass(frozen=True, slots=True)
class Move(Frozen):
    """``Y#.n`` (move, next line doesn't wait), ``Q#.n`` (push), ``Z#.n`` (push, no wait).

    2.2.2 "Y", "Q", "Z"; ``index`` is a P memory number.
    """

    kind: Literal["Y", "Q", "Z"]
    index: int | None = None
    motor: int | None = None
    modifier: Modifier = None


@dataclass(frozen=True, slots=True)
class Interp(Frozen):
    """``@#.n`` with ``+`` (CW) or ``-`` (CCW): circular/linear interpolation (2.1.2 "@")."""

    index: int | None = None
    motor: int | None = None
    direction: Modifier = None


ExecOp = Literal[
    "go",             # ^   execute direct motion (2.1.2)
    "origin",         # |   origin search
    "go_origin",      # |1  move to position 0
    "set_origin",     # |2  current position := 0
    "enable",         # (
    "free",           # )
    "pause",          # ]   pause program bank / stop all motors
    "pause_motor",    # ]1  pause one motor in a chain
    "stop_after_line",  # }
    "estop",          # *
    "estop_release",  # *1
    "next_line",      # >
    "prev_line",      # <
    "save",           # $
]


@dataclass(frozen=True, slots=True)
class Exec(Frozen):
    """A one-symbol execution command (2.1.2, 6.5)."""

    op: ExecOp
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class Output(Frozen):
    """``O#.n`` (on) / ``F#.n`` (off) (2.1.2)."""

    on: bool
    index: int
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class OutputWord(Frozen):
    """``O.n=X``: set 16 outputs at once (Modbus FC15 generation, 5.6.7)."""

    value: Expr
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class Capture(Frozen):
    """``#x.n``: store the current position in P memory x (2.1.2 "#")."""

    index: int
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class StartBank(Frozen):
    """``[#.n`` program bank, ``[L#.n`` ladder bank, ``[LM#.n`` logic motion bank.

    ``index is None`` means resume the paused bank (``[``, ``[L``).
    """

    kind: Literal["B", "L", "LM"]
    index: int | None = None
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class StopBank(Frozen):
    """``]L.n`` (pause; twice stops) and ``]LM.n`` (ladder / logic motion)."""

    kind: Literal["L", "LM"]
    motor: int | None = None


QueryLetter = Literal["A", "S", "M", "T", "V", "P", "N", "R", "L"]


@dataclass(frozen=True, slots=True)
class Query(Frozen):
    """A ``?`` query (6.6).

    * ``?.1``          -> ``letter=None, number=None`` (direct mode data)
    * ``?96.1``        -> ``number=96``
    * ``?3.1``         -> ``number=3`` (program bank 3 listing)
    * ``?A.1``         -> ``letter="A"`` (all A data)
    * ``?L3.1``        -> ``letter="L", number=3`` (ladder bank 3 listing)
    * ``?1000.1``      -> ``number=1000``
    """

    number: int | None = None
    letter: str | None = None
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class Call(Frozen):
    """``C#`` call, ``J#`` jump, ``CL#`` ladder call, ``JL#`` ladder jump (2.2.2, 2.2.3)."""

    kind: Literal["C", "J", "CL", "JL"]
    index: int
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class Loop(Frozen):
    """``X#.n``: loop the following lines ``count`` times (0 = forever) (2.2.2 "X")."""

    count: int
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class LoopEnd(Frozen):
    """``X.n-``: end of the innermost loop."""

    motor: int | None = None


@dataclass(frozen=True, slots=True)
class Wait(Frozen):
    """``W#.n``: in a branch, wait up to T# while the condition stays true (W0 forever)."""

    index: int
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class BankBegin(Frozen):
    """``B#.n`` / ``L#.n``: start of a bank definition (2.2.2 "B", 2.2.3 "L")."""

    ladder: bool
    index: int
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class ClearBanks(Frozen):
    """``B100`` / ``L100``: clear all program / ladder banks (cm-banks-rt3.txt 2.3, 3.2)."""

    ladder: bool
    motor: int | None = None


@dataclass(frozen=True, slots=True)
class BankEnd(Frozen):
    """``END`` / ``END.n``: end of a bank definition."""

    motor: int | None = None


@dataclass(frozen=True, slots=True)
class Alloc(Frozen):
    """``\\P300`` / ``\\N200``: P/N/R data area allocation (2.1.2 "\\")."""

    kind: Literal["P", "N"]
    count: int


@dataclass(frozen=True, slots=True)
class Branch(Frozen):
    """``condition, then, else`` with ``:`` junctions (2.2.2 "I"/"V", 4.2.2).

    ``then`` and ``orelse`` are tuples of statements joined by ``:``.
    ``orelse`` is empty when the line gives no else part.
    """

    condition: Expr
    then: tuple[Statement, ...]
    orelse: tuple[Statement, ...] = ()


Statement = (
    Assign | Ref | Move | Interp | Exec | Output | OutputWord | Capture | StartBank | StopBank |
    Query | Call | Loop | LoopEnd | Wait | BankBegin | ClearBanks | BankEnd | Alloc | Branch
)


@dataclass(frozen=True, slots=True)
class Line(Frozen):
    """One logical line: statements separated by commas (2.2.2 ", (comma)").

    ``joined`` is true when the line ends with ``;``: in a program bank the next
    line merges with this one; in a ladder bank the results of assignments are
    not displayed (cm-banks-rt3.txt 1.1 ";").
    ``source`` keeps the raw text (without comment) for error messages and the
    40-character check.
    """

    statements: tuple[Statement, ...]
    joined: bool = False
    source: str = ""

    @property
    def empty(self) -> bool:
        return not self.statements


def inner_motor(stmt: Statement) -> int | None:
    """The motor ID a statement names (None when it names none)."""
    if isinstance(stmt, Assign):
        return stmt.target.motor
    if isinstance(stmt, Ref):
        return stmt.reg.motor
    return getattr(stmt, "motor", None)
