"""The device API: the one narrow door into the motor model.

Every front end goes through it: the text line (via :attr:`Device.host_line`),
Modbus, EtherCAT, EtherNet/IP, the web page and the in-process Python API.
None of them re-implements motor behaviour; they translate their protocol to
these calls and map :mod:`coolmuscle.errors` exceptions to their own error form.

The concrete implementation is :class:`coolmuscle.chain.daisy.Chain`.  All calls must
come from the thread that drives the kernel (the asyncio loop in ``sim``).
See docs/device-api.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Literal, Protocol, runtime_checkable

from .hostline import HostLine
from ..sim.kernel import Kernel

EventKind = Literal["reply", "status", "input", "output", "message", "origin", "alarm"]
Origin = Literal["host", "api", "modbus", "bank", "ladder", "motor", "fieldbus", "web"]


@dataclass(frozen=True, slots=True)
class Event:
    """Something the motor said or did, stamped with virtual time.

    ``text`` is the line exactly as the motor prints it on the host line
    (without delimiter).  ``value`` carries the number where there is one
    (the Ux value of a status report, the input word of an input report).
    """

    time: int
    motor: int
    kind: EventKind
    text: str
    value: int | None = None
    origin: Origin = "motor"


@dataclass(frozen=True, slots=True)
class MotorSnapshot:
    """Typed live values of one motor (6.6 queries), read at the current instant."""

    motor: int
    time: int
    position: int          # ?96 Px, pulses
    target: int            # PT, pulses
    position_error: int    # ?95 Pe, pulses
    speed: int             # ?97 Sx, speed units of K37
    speed_pps: float       # pulses per second
    torque: int            # ?98 Ix, % of rated
    status: int            # ?99 Ux
    inputs: int            # ?70 word, bit0 = input 1
    outputs: int           # ?50 word, bit0 = output 1
    temperature: int       # ?71 degC
    voltage: int           # ?72 0.1 V
    analog: int            # ?74 0..1023
    encoder_count: int     # ?76 Ecnt
    enabled: bool = True
    extra: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class CyclicState:
    """What a fieldbus cycle reads of one motor every cycle: the cheap part of
    :class:`MotorSnapshot` (the EtherCAT bridge's TxPDO 6064h and statusword 6041h,
    ethercat-bridge-users-guide.txt 6.1-6.5, and its homing and CMD-mode watch)."""

    motor: int
    time: int
    position: int          # ?96 Px, pulses
    speed_pps: float       # pulses per second
    status: int            # ?99 Ux
    inputs: int            # ?70 word, bit0 = input 1
    outputs: int           # ?50 word, bit0 = output 1
    enabled: bool
    origin_search: bool    # 5.3 running
    origin_done: bool      # 5.3 completed since the last |


EventListener = Callable[[Event], None]


@runtime_checkable
class TargetStream(Protocol):
    """Cyclic position mode: a stream of target positions (EtherCAT csp later)."""

    def push(self, target: int) -> None:
        """Set the next target position (pulses); the motor follows it."""

    def close(self) -> None:
        """Leave cyclic position mode; the motor holds its position."""


@runtime_checkable
class Device(Protocol):
    """What every front end may call.  Implemented by :class:`coolmuscle.chain.daisy.Chain`."""

    kernel: Kernel
    host_line: HostLine

    @property
    def motor_ids(self) -> tuple[int, ...]:
        """IDs on the chain, 1..N."""

    def execute(self, line: str, *, origin: Origin = "api",
                motor: int | None = None, session: object = None) -> list[str]:
        """Run one CML line as if sent by ``origin``; return the reply lines it produced
        at once (queries, error messages).  Later events arrive via :meth:`subscribe`.
        Statements without ``.n`` go to ``motor`` (default ID1).  ``session`` names
        the sender within ``origin``: a bank upload (``B#.n``) takes only the lines
        of the sender that opened it."""

    def get_param(self, motor: int, k: int) -> int:
        """Read K parameter ``k`` of ``motor``."""

    def set_param(self, motor: int, k: int, value: int) -> None:
        """Write K parameter ``k``; raises :class:`~coolmuscle.errors.OutOfRangeError`."""

    def get_register(self, motor: int, kind: str, index: int) -> int | str:
        """Read data memory (P S A M T V N R H).  A V string reads as ``'"abcd"'``."""

    def register_value(self, motor: int, kind: str, index: int) -> int:
        """The number a register stands for: V strings packed, V states read live."""

    def set_register(self, motor: int, kind: str, index: int, value: int | str) -> None:
        """Write data memory; raises ``OutOfRangeError``/``LookupError`` when invalid."""

    def snapshot(self, motor: int) -> MotorSnapshot:
        """Live typed values of one motor."""

    def cyclic_state(self, motor: int) -> CyclicState:
        """The few live values a fieldbus reads every cycle (cheaper than a snapshot)."""

    def set_input(self, motor: int, number: int, on: bool) -> None:
        """Drive the electrical level of input ``number`` (1..6)."""

    def set_analog(self, motor: int, counts: int) -> None:
        """Drive the analog input, 0..1023 (6.6 ?74)."""

    def subscribe(self, listener: EventListener) -> Callable[[], None]:
        """Receive every :class:`Event`; returns an unsubscribe function."""

    def target_stream(self, motor: int) -> TargetStream:
        """Enter cyclic position mode for ``motor``."""

    def inject_fault(self, motor: int, fault: str, **params: object) -> None:
        """Inject a fault now (see docs/machine-file.md for names)."""

    def save(self, motor: int) -> None:
        """Same as ``$.n``: store parameters, data and banks."""
