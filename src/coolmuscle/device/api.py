"""The device API: the one narrow door into the motor model.

Every front end and tool goes through it: the text line (via :attr:`Device.host_line`),
Modbus (RTU on COM0 and COM1, TCP), EtherCAT, EtherNet/IP, the web page, the script
runner, traces and plots, and the in-process Python API.  None of them re-implements
motor behaviour; they translate their protocol to these calls and map
:mod:`coolmuscle.errors` exceptions to their own error form.

The concrete implementation is :class:`coolmuscle.chain.daisy.Chain`.  All calls must
come from the thread that drives the kernel (the asyncio loop in ``sim``).
See docs/device-api.md.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, NamedTuple, Protocol, runtime_checkable

from ..sim.kernel import Kernel
from .hostline import ByteListener, HostLine

if TYPE_CHECKING:
    from ..motor.state.firmware import Firmware
    from .trace import TraceFeed
    from .wire.schedule import WireFaults

EventKind = Literal["reply", "status", "input", "output", "message", "origin", "alarm",
                    "wire"]
Origin = Literal["host", "api", "modbus", "bank", "ladder", "motor", "fieldbus", "web"]


class Event(NamedTuple):
    """Something the motor said or did, stamped with virtual time.

    ``text`` is the line exactly as the motor prints it on the host line
    (without delimiter).  ``value`` carries the number where there is one
    (the Ux value of a status report, the input word of an input report).

    A named tuple, as :class:`CyclicState`: every in-position of every axis of a csp
    stream makes one, and a frozen dataclass's constructor (one ``object.__setattr__``
    a field) costs five times as much.
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
    #: ``position``, ``position_error`` and ``torque`` before they are rounded (what the
    #: twin's fit compares: coolmuscle.tools.twin)
    position_exact: float = 0.0
    position_error_exact: float = 0.0
    torque_exact: float = 0.0
    extra: dict[str, int] = field(default_factory=dict)


class CyclicState(NamedTuple):
    """What a fieldbus cycle reads of one motor every cycle: the cheap part of
    :class:`MotorSnapshot` (the EtherCAT bridge's TxPDO 6064h and statusword 6041h,
    ethercat-bridge-users-guide.txt 6.1-6.5, and its homing and CMD-mode watch).

    A named tuple, not a frozen dataclass: read as often as every axis of a segment
    every millisecond, and a frozen dataclass's constructor (one ``object.__setattr__``
    a field) costs about 2 us of the 1 ms cycle an axis."""

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

#: Builds a device as :class:`coolmuscle.chain.daisy.Chain` does: ``factory(kernel,
#: motors, firmware=..., state_dir=..., pacing=..., machine=...)`` (the command line, the
#: ``coolmuscle://`` URL and the twin take one; tests and embedders hand their own).
ChainFactory = Callable[..., "Device"]


@runtime_checkable
class TargetStream(Protocol):
    """Cyclic position mode: a stream of target positions (EtherCAT csp later)."""

    def push(self, target: int) -> None:
        """Set the next target position (pulses); the motor follows it."""

    def close(self) -> None:
        """Leave cyclic position mode; the motor holds its position."""


@runtime_checkable
class Com1Line(Protocol):
    """COM1 of the final motor as a front end sees it: a Modbus host while the final
    motor's K84 is 1 (5.6.6), at its K65 baud rate and K82 parity
    (:class:`coolmuscle.chain.firmware_modbus.master.Com1Port`)."""

    def feed(self, data: bytes) -> None:
        """Bytes the slave device on COM1 sent, arrived now."""

    def add_listener(self, listener: ByteListener) -> Callable[[], None]:
        """Receive every byte the motor sends on COM1; returns an unsubscribe function."""

    def baud(self) -> int:
        """Bits per second of COM1 (the final motor's K65)."""

    def parity(self) -> str:
        """``"N"``, ``"E"`` or ``"O"`` (the final motor's K82)."""


@runtime_checkable
class Device(Protocol):
    """What every front end may call.  Implemented by :class:`coolmuscle.chain.daisy.Chain`."""

    kernel: Kernel
    #: COM0: ``feed(bytes)`` in, ``add_listener(callback)`` out (docs/device-api.md)
    host_line: HostLine

    @property
    def com1(self) -> Com1Line:
        """COM1 of the final motor (5.6.6, docs/modbus.md)."""

    @property
    def firmware(self) -> Firmware:
        """The firmware profile of ID1 (CM2, RT3 or CM1: parameters, I/O, Modbus)."""

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

    def target_stream(self, motor: int, period_ns: int = 0) -> TargetStream:
        """Enter cyclic position mode for ``motor``; ``period_ns``: the targets come one
        each period (csp's cycle), which a stepper ramps over (0: not known)."""

    def inject_fault(self, motor: int, fault: str, **params: object) -> None:
        """Inject a fault now (see docs/machine-file.md for names)."""

    @property
    def wire_faults(self) -> WireFaults:
        """The wire faults of this device (docs/wire-faults.md): every door asks it what
        to do to the messages it sends; the state lives here, in virtual time."""

    def inject_wire_fault(self, door: str, kind: str, *, at: float = 0.0,
                          until: float | None = None, every: int | None = None,
                          probability: float | None = None, seed: int | None = None,
                          count: int | None = None, motor: int | None = None,
                          **params: object) -> int:
        """Install a wire fault of ``door`` (``host-line``, ``chain``, ``modbus-rtu``,
        ``modbus-tcp``, ``enip``, ``ethercat``) ``at`` seconds from now, until ``until``
        seconds from now; returns its number.  ``ValueError`` for an unknown door, kind
        or parameter."""

    def clear_wire_faults(self, fault: int | None = None, *, door: str | None = None) -> int:
        """End wire faults: number ``fault``, those of ``door``, or all; how many ended."""

    def machine_data(self, motor: int) -> dict[str, float]:
        """The load and drive data ``motor`` runs with, by the keys of a machine
        file's ``[axis.load]`` and ``[axis.drive]`` (docs/machine-file.md)."""

    def load_machine(self, machine: str | os.PathLike[str]) -> None:
        """Install a machine file (docs/machine-file.md) on the motors it names;
        raises :class:`~coolmuscle.chain.machine.MachineFileError`."""

    def observe(self, observer: Callable[[], None]) -> Callable[[], None]:
        """Call ``observer()`` whenever state may have changed outside a kernel event
        (a host line, an API call); returns a remover.  Kernel events are observed
        with ``kernel.add_observer``."""

    def trace_feed(self) -> TraceFeed:
        """Start recording every motor: exact values at any instant from now on, and
        every change (:class:`coolmuscle.device.trace.TraceFeed`)."""

    def modbus_request(self, unit: int, pdu: bytes, *, tcp: bool = False) -> bytes | None:
        """The response PDU the chain's Modbus map (5.6.7) gives to ``pdu`` sent to
        station ``unit``, or ``None`` (no reply: another station, a broadcast).
        ``tcp``: the Modbus TCP door, which answers while COM0 speaks text too."""

    def modbus_station(self) -> int:
        """The station COM0 answers as while it speaks Modbus RTU (ID1's K81, 5.6.1),
        0 while it speaks CML text."""

    def save(self, motor: int) -> None:
        """Same as ``$.n``: store parameters, data and banks."""

    def close(self) -> None:
        """Close the saved state (once, when done; unsaved data is lost, as at
        power off)."""
