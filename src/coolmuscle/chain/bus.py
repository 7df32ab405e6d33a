"""The chain's event bus, its bank waits and its host line settings (compiled).

Every move passes here: its arrival's status report (:meth:`ChainBus.emit`, on the host
line and to the subscribers of the device API), the wake-ups of the bank lines that
wait for it (:meth:`ChainBus.poke`, :meth:`ChainBus.watch`) and the K23/K70/K20/K81
settings of each line sent.  :class:`ChainBus` is the :class:`~coolmuscle.motor.core.MotorBus`
every motor of the chain is handed: the motors call it directly on their hot path,
and it hands the chain-wide commands (``]``, ``[``, ``?#``, ``$``, COM1) on to the
:class:`ChainCommands` it was built with.  The :class:`~coolmuscle.chain.daisy.Chain`
builds one and holds it (composition; the chain itself stays a plain class that front
ends and the trace recorder may keep weak references to).  This module is compiled
with the hot modules (coolmuscle/_accel.py, docs/performance.md "Compiled hot modules").
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Final, Protocol

from ..cml import ast
from ..device.api import CyclicState, Event, EventListener
from ..device.hostline import BAUD_RATES, PARITY_OF_K82, HostLine, LineSettings
from ..device.uart import PLAIN, Frame
from ..errors import NoSuchMotorError
from ..motor.context import Context
from ..motor.status import Report
from ..sim.kernel import PRIO_REPORT, Kernel
from ..sim.memo import Key, Memo
from .links import ChainLinks

if TYPE_CHECKING:
    from ..motor.core import MotorCore
    from ..motor.motor import Motor

log = logging.getLogger("coolmuscle.chain.daisy")

_NO_ECHO: Final = int(Report.NO_ECHO)


def _frame_of_k82(k82: int) -> Frame:
    """The frame of the host line: 8 data bits, K82's parity, 1 stop bit (5.6.1; a
    firmware without K82 reads it 0: no parity)."""
    parity = PARITY_OF_K82.get(k82, "N")
    return PLAIN if parity == "N" else Frame(parity=parity)


#: Origins whose replies are printed on the host line (docs/device-api.md).
HOST_LINE_ORIGINS: Final = frozenset({"host", "bank", "ladder", "motor"})

#: A bank wait: its callback and the motors it waits for (``None``: any poke).
Watcher = tuple[Callable[[], None], frozenset[int] | None]


class ChainCommands(Protocol):
    """What acts on the whole chain rather than on one motor (the chain implements it):
    the part of :class:`~coolmuscle.motor.core.MotorBus` the bus hands on."""

    def chain_command(self, motor: MotorCore, stmt: ast.Exec, ctx: Context) -> None:
        """Chain-wide execution commands (``]``, ``*``, ``*1`` ...; 2.1.2)."""

    def bank_command(self, motor: MotorCore, stmt: ast.Statement, ctx: Context) -> None:
        """Bank execution commands: ``[`` ``]L`` ``B100`` ... (6.5; RT3 2.3, 3.2)."""

    def bank_query(self, motor: MotorCore, query: ast.Query) -> list[str] | None:
        """Bank listings ``?#``, ``?L#``, ``?1000`` (6.6)."""

    def save(self, motor: int) -> None:
        """``$``: store parameters, data and banks of motor ``motor`` (2.1.2)."""

    def beyond_chain(self, motor_id: int, stmt: ast.Statement, ctx: Context) -> bool:
        """A statement for an ID not on the chain (the COM1 Modbus slave, 5.6.6)."""


class ChainBus:
    """Events, bank waits, line settings and chain timing of a chain of ``count``
    motors (the chain fills :attr:`motors` right after building it, before power-up).

    ``on_line`` is called with each complete host line; ``commands`` takes the
    chain-wide commands of :class:`ChainCommands`."""

    def __init__(self, kernel: Kernel, count: int, on_line: Callable[[str], None],
                 commands: ChainCommands, *, pacing: bool = False) -> None:
        self.kernel = kernel
        self.motors: dict[int, Motor] = {}
        self.commands = commands
        self._listeners: list[EventListener] = []
        self._watchers: list[Watcher] = []
        #: The watchers naming each motor, in the order they came (:meth:`poke` about one
        #: motor looks only there while no watcher listens to every motor).
        self._watching: dict[int, list[Watcher]] = {}
        self._everywhere = 0            # watchers without ``motors``
        self._settings_cache: Memo[Key, LineSettings] = Memo(64)
        self._settings_now = LineSettings()
        self._settings_version = -1     # ID1's params.version of _settings_now
        self.host_line = HostLine(kernel, on_line, self._line_settings, pacing=pacing)
        self.links = ChainLinks(count, self._k65)
        #: The first ID the host line cannot reach (a motor powered off, a broken link:
        #: the chain's wire faults, chain/power.py); 0 while it reaches every motor.
        self.cut_from = 0

    # -- the motors ---------------------------------------------------------------------
    @property
    def motor_ids(self) -> tuple[int, ...]:
        return tuple(self.motors)

    def motor(self, motor_id: int) -> Motor | None:
        """The motor with ``motor_id``, or ``None`` when it is not on the chain."""
        return self.motors.get(motor_id)

    def require(self, motor_id: int) -> Motor:
        """The motor with ``motor_id``; :class:`NoSuchMotorError` when it is not there."""
        motor = self.motors.get(motor_id)
        if motor is None:
            ids = self.motor_ids
            raise NoSuchMotorError(f"no motor ID{motor_id} on this chain "
                                   f"(IDs {ids[0]}..{ids[-1]})")
        return motor

    def get_param(self, motor: int, k: int) -> int:
        """K parameter ``k`` of ``motor`` (the device API's ``get_param``)."""
        return self.require(motor).k(k)

    def cyclic_state(self, motor: int) -> CyclicState:
        """What a fieldbus cycle reads of ``motor`` (the device API's ``cyclic_state``:
        every axis of an EtherCAT segment every millisecond, so compiled here)."""
        # tuple.__new__ is what the named tuple's own __new__ calls; called here, the
        # compiled code builds it without that Python-level function
        return tuple.__new__(CyclicState, self.require(motor).cyclic_values(self.kernel.now))

    # -- the host line ----------------------------------------------------
    def _line_settings(self) -> LineSettings:
        first = self.motors[1]
        version = first.params.version
        if version == self._settings_version:       # ID1's K values unchanged since
            return self._settings_now
        no_echo, k70, k20, modbus, k82 = first.k(23) & _NO_ECHO, first.k(70), \
            first.k(20), first.k(81) != 0, first.k(82)
        key: Key = (no_echo, k70, k20, modbus, k82)
        found = self._settings_cache.get(key)    # read at every line sent: no new object
        if found is None:
            found = self._settings_cache.put(key, LineSettings(
                echo=not no_echo, delimiter=b"\r\n" if k70 == 1 else b"\r",
                baud=BAUD_RATES.get(k20, 38400), modbus=modbus, frame=_frame_of_k82(k82)))
        self._settings_now, self._settings_version = found, version
        return found

    # -- chain timing (ch. 3 K65; .links) ----------------------------------------------
    def _k65(self) -> int:
        """ID1's K65: the baud rate of every link (ch. 3 K65)."""
        return self.motors[1].k(65)

    @property
    def paced(self) -> bool:
        """Wire-time pacing is on: bytes take their time on the host line and the links."""
        return self.host_line.pacing

    def relay(self, src: int, dst: int, nbytes: int) -> int:
        """When ``nbytes`` ID ``src`` sends now reach ID ``dst`` (now without pacing)."""
        now = self.kernel.now
        return self.links.arrival(src, dst, nbytes, now) if self.paced else now

    # -- bank waits (W#, program lines): re-checked on events, never polled -------
    def watch(self, callback: Callable[[], None],
              motors: Iterable[int] | None = None) -> Callable[[], None]:
        """Call ``callback`` at every :meth:`poke` until the returned remover is called;
        with ``motors``, only at pokes about one of them (or about nothing in particular):
        a bank line waiting for motions is not woken by the other motors' milestones."""
        entry: Watcher = (callback, None if motors is None else frozenset(motors))
        self._watchers.append(entry)
        if entry[1] is None:
            self._everywhere += 1
        else:
            for m in entry[1]:
                self._watching.setdefault(m, []).append(entry)

        def remove() -> None:
            if entry in self._watchers:
                self._watchers.remove(entry)
                if entry[1] is None:
                    self._everywhere -= 1
                else:
                    for m in entry[1]:
                        self._watching[m].remove(entry)
        return remove

    def poke(self, motor: int | None = None) -> None:
        """Something changed (a line, an input, a motion, a ladder scan): look again.
        ``motor``: only the motion of that motor changed.  The watchers run in the order
        they came, each once, those of this poke even if one of them removes another."""
        if not self._watchers:
            return
        if motor is None or self._everywhere:
            for callback, motors in list(self._watchers):
                if motors is None or motor is None or motor in motors:
                    callback()
            return
        naming = self._watching.get(motor)
        if naming:                      # the same watchers, in the same order
            for callback, _ in list(naming):
                callback()

    # -- events -------------------------------------------------------------
    def emit(self, motor: int, kind: str, text: str, value: int | None = None,
             origin: str = "motor") -> None:
        """Report a line: on the host line (per origin) and to every subscriber."""
        cut = self.cut_from
        if origin in HOST_LINE_ORIGINS and not (cut and motor >= cut):
            hop_from = min(motor, len(self.motors))
            if self.paced and hop_from > 1:     # back up the chain to ID1 (ch. 3 K65)
                size = len(text) + len(self._line_settings().delimiter)
                at = self.links.arrival(hop_from, 1, size, self.kernel.now)
                self.kernel.schedule_at(at, lambda: self.host_line.send_line(text),
                                        priority=PRIO_REPORT, name="chain-reply")
            else:
                self.host_line.send_line(text)
        if not self._listeners:              # nobody subscribed: no event to hand out
            return
        # tuple.__new__: the named tuple built without its Python-level __new__ (compiled)
        event = tuple.__new__(Event, (self.kernel.now, motor, kind, text, value, origin))
        for listener in list(self._listeners):
            try:
                listener(event)
            except Exception:
                log.exception("event listener failed")

    def subscribe(self, listener: EventListener) -> Callable[[], None]:
        """Hand every :class:`~coolmuscle.device.api.Event` to ``listener``; returns a
        remover."""
        self._listeners.append(listener)

        def remove() -> None:
            if listener in self._listeners:
                self._listeners.remove(listener)
        return remove

    # -- chain-wide commands: handed on (cold paths) ----------------------------------
    def chain_command(self, motor: MotorCore, stmt: ast.Exec, ctx: Context) -> None:
        self.commands.chain_command(motor, stmt, ctx)

    def bank_command(self, motor: MotorCore, stmt: ast.Statement, ctx: Context) -> None:
        self.commands.bank_command(motor, stmt, ctx)

    def bank_query(self, motor: MotorCore, query: ast.Query) -> list[str] | None:
        return self.commands.bank_query(motor, query)

    def save(self, motor: int) -> None:
        self.commands.save(motor)

    def beyond_chain(self, motor_id: int, stmt: ast.Statement, ctx: Context) -> bool:
        return self.commands.beyond_chain(motor_id, stmt, ctx)


class MotorStream:
    """Cyclic position mode for one motor (the device API's ``target_stream``): each
    target pushed goes to the motor's :meth:`~coolmuscle.motor.motor.Motor.follow`."""

    def __init__(self, motor: Motor, period_ns: int = 0) -> None:
        self._motor = motor
        self._period = period_ns
        self.closed = False

    def push(self, target: int) -> None:
        if not self.closed:
            self._motor.follow(float(target), self._period)

    def close(self) -> None:
        self.closed = True
