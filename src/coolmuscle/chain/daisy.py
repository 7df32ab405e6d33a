"""The daisy chain of motors behind one host line; implements the device API.

The host line enters at ID1 and every statement goes to the motor its ``.n`` names
(cml-users-guide.txt 1.1 "up to 15 motors can be controlled on a single network").
A statement without an ID goes to ID1 in direct mode.  A statement for an ID that is
not on the chain goes around the chain unanswered (docs/fidelity.md "Daisy chain"),
unless it is for "final ID + 1" while COM1 is a Modbus host (5.6.6, :mod:`.modbus`).

:class:`Chain` is the :class:`coolmuscle.device.api.Device` every front end uses: every
member of the device API is defined here.  Its event bus, bank waits, host line settings
and chain timing are a compiled :class:`.bus.ChainBus` it builds and holds
(:attr:`Chain.bus`); the motors are handed that bus, their hot path, and the bus hands
the chain-wide commands back to the chain (:class:`.bus.ChainCommands`).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

from ..cml import ast
from ..cml.ast import inner_motor
from ..cml.parser import parse
from ..device.api import CyclicState, EventListener, MotorSnapshot, TargetStream
from ..device.wire.chain import cut_from
from ..device.wire.line import LineFaults
from ..device.wire.schedule import ActiveFault, WireFault, WireFaults, WireRecord, wire_fault
from ..errors import (
    CmlSyntaxError,
    MotorError,
    NoLadderBankError,
    NoProgramBankError,
    OutOfRangeError,
    StoreError,
)
from ..motor.context import Context
from ..motor.motion.dynamics import MotionMemos
from ..motor.motor import Motor
from ..motor.programs.banks import BankUploads
from ..motor.programs.coordinated import LINE_PAIRS, end_of_line, pair_line
from ..motor.programs.direct import MotorEval, run_statement
from ..motor.programs.evaluate import evaluate
from ..motor.state.firmware import get_firmware
from ..motor.state.memory import VNumber, VState
from ..motor.state.store import Store, bad_state_message, snapshot_problem
from ..motor.status import Report
from ..sim.kernel import PRIO_IO, Kernel
from ..sim.memo import Memo
from .bus import ChainBus, ChainCommands, MotorStream
from .power import power_off, power_on_again

if TYPE_CHECKING:
    from ..device.api import Device
    from ..device.banklines import BankLineListener
    from ..device.trace import TraceFeed
    from ..motor.core import MotorBus, MotorCore
    from .banklines import BankLineObservers
    from .machine import Machine

log = logging.getLogger(__name__)

#: Origins whose lines travel the chain from ID1 (the host line, a bank or ladder line
#: of a motor for another): a motor powered off or beyond a broken link never gets them.
_THROUGH_ID1 = frozenset({"host", "bank", "ladder"})


class Chain:
    """Motors 1..N behind one host line: the device API (:class:`~coolmuscle.device.api.Device`).

    Its event bus, bank waits, host line settings and chain timing are :attr:`bus`
    (:class:`.bus.ChainBus`, compiled), which the motors are handed; :attr:`motors`,
    :attr:`host_line` and :attr:`links` are the bus's."""

    def __init__(self, kernel: Kernel | None = None, motors: int = 1, *,
                 firmware: str = "cm2", state_dir: Path | str | None = None,
                 pacing: bool = False,
                 machine: str | os.PathLike[str] | Machine | None = None) -> None:
        if not 1 <= motors <= 15:
            raise ValueError("a chain has 1 to 15 motors (cml-users-guide.txt 1.1)")
        self.kernel = kernel or Kernel()
        per_motor = firmware.split(",")   # "cm1,cm1,cm2,cm2": one profile per motor (EB12)
        self.firmware = get_firmware(per_motor[0])
        self.bus = ChainBus(self.kernel, motors, self._on_host_line, self, pacing=pacing)
        self.motors = self.bus.motors
        self.host_line = self.bus.host_line
        self.links = self.bus.links
        # A fieldbus reads every axis every cycle (an EtherCAT segment: 32 axes each
        # millisecond): these reads go straight to the compiled bus, without a frame of
        # this class's own (the methods below say the same, for the reader and the types).
        self.cyclic_state = self.bus.cyclic_state  # type: ignore[method-assign]
        self.get_param = self.bus.get_param  # type: ignore[method-assign]
        self._observers: list[Callable[[], None]] = []
        #: Lines parsed lately (the syntax tree is frozen, so a tree can serve again): a
        #: host or PLC sends the same few lines over and over.  Errors are not kept.
        self._parsed: Memo[str, tuple[ast.Line, ...]] = Memo(256)
        #: The plans and solved motions of the chain, shared by its motors.
        self.motion_memos = MotionMemos()
        self._bank_lines: BankLineObservers | None = None   # observe_bank_lines
        self.state_dir = Path(state_dir) if state_dir else None
        self.store = (Store(self.state_dir / "coolmuscle.sqlite3", writer=True)
                      if self.state_dir else None)
        #: What ``$`` saved, by motor, when there is no store: a power cycle (a wire
        #: fault) brings it back within the run (docs/wire-faults.md)
        self._saved: dict[int, dict[str, object]] = {}
        #: Wire faults at every door (docs/wire-faults.md): the doors ask it
        self.wire_faults = WireFaults(self.kernel)
        self.wire_faults.listen(self._wire_record)
        self.wire_faults.watch("chain", self._chain_fault)
        #: The first ID cut off from ID1 (the bus's ``cut_from``, read here in plain
        #: Python on every line: an attribute of the compiled bus costs more)
        self._cut = 0
        try:
            self._build(motors, per_motor, machine)
        except BaseException:      # a damaged store, a bad machine file: let the state go
            self.close()
            raise

    def _build(self, motors: int, per_motor: list[str],
               machine: str | os.PathLike[str] | Machine | None) -> None:
        for motor_id in range(1, motors + 1):
            profile = self.firmware if len(per_motor) == 1 else \
                get_firmware(per_motor[min(motor_id, len(per_motor)) - 1])
            self.motors[motor_id] = Motor(motor_id, self.kernel, profile, self.bus,
                                          self.motion_memos)
        self.uploads = BankUploads(self.motors)
        self.host_line.on_source_end = self._source_ended
        self.motors[1].params.on_change(
            lambda k, _old, new: self._k65_written(new) if k == 65 else None)
        self._attach_modbus()
        self._restore()
        if machine is not None:           # wired before power-up (K46 odd searches then)
            self.load_machine(machine)
        for motor in self.motors.values():
            if self.wire_faults.lasting("chain", "power_off", motor.id) is None:
                motor.power_on()          # one a machine file keeps off powers up later

    # -- device API: identity -------------------------------------------------------
    @property
    def motor_ids(self) -> tuple[int, ...]:
        """IDs on the chain, 1..N."""
        return tuple(self.motors)

    def motor(self, motor_id: int) -> Motor | None:
        """The motor with ``motor_id``, or ``None`` (model code: the machine file)."""
        return self.motors.get(motor_id)

    @property
    def paced(self) -> bool:
        """Wire-time pacing is on: bytes take their time on the host line and the links."""
        return self.host_line.pacing

    def load_machine(self, machine: str | os.PathLike[str] | Machine) -> None:
        """Install a machine file (docs/machine-file.md) on the motors it names: its
        path, or one :func:`.machine.load_machine` or :func:`.machine.parse_machine` read."""
        from .machine import Machine, apply_machine, load_machine
        apply_machine(machine if isinstance(machine, Machine) else load_machine(Path(machine)),
                      self)
        self._changed()

    # -- the host line ----------------------------------------------------
    def _source_ended(self, source: object) -> None:
        """A host line sender went away: an upload it left open is dropped."""
        self.uploads.abandon("host", source)

    def _on_host_line(self, text: str) -> None:
        self._execute_text(text, Context(origin="host", session=self.host_line.source))
        self._changed()

    def observe(self, observer: Callable[[], None]) -> Callable[[], None]:
        """Call ``observer()`` whenever state may have changed outside a kernel event
        (a host line, an API call; trace recorders); returns a remover.  Kernel events
        are observed with ``kernel.add_observer``."""
        self._observers.append(observer)
        return lambda: self._observers.remove(observer) if observer in self._observers else None

    def observe_bank_lines(self, listener: BankLineListener) -> Callable[[], None]:
        """Tell ``listener`` of every bank line run from now on (device/banklines.py);
        returns its remover.  Unobserved, the banks run as if this did not exist."""
        if self._bank_lines is None:
            from .banklines import BankLineObservers
            self._bank_lines = BankLineObservers(self.kernel, self.motors)
        return self._bank_lines.add(listener)

    def _changed(self) -> None:
        """State may have changed outside a kernel event: let the observers look."""
        for observer in self._observers:
            observer()

    def execute(self, line: str, *, origin: str = "api", motor: int | None = None,
                session: object = None) -> list[str]:
        """Run a CML line as ``origin``; return the replies it produced at once.

        ``motor`` is the ID statements without ``.n`` go to (default ID1).
        ``session`` names the sender within ``origin`` (a bank upload ``B#.n``
        takes only the lines of the sender that opened it).
        """
        ctx = Context(origin=origin, replies=[], session=session,
                      default_motor=1 if motor is None else self.bus.require(motor).id)
        self._execute_text(line, ctx)
        self._changed()
        return ctx.replies or []

    def _execute_text(self, text: str, ctx: Context) -> None:
        if self.uploads.consume(text, ctx):   # a bank definition is being typed
            return
        if self._baud_answer(text):
            return
        try:
            lines = self._parse(text)
        except CmlSyntaxError as error:
            self.motors.get(ctx.default_motor, self.motors[1]).report_error(ctx, error)
            return
        if self.uploads.begins(lines, ctx):    # B#.n / L#.n (2.2.2, 2.2.3)
            return
        routed = [[(stmt, inner_motor(stmt) or ctx.default_motor) for stmt in line.statements]
                  for line in lines]
        arrivals = (self._arrivals(routed, len(text) + 1)
                    if ctx.origin == "host" and self.paced else {})
        for line in routed:
            pairs = pair_line(line, self.motors.__contains__, arrivals)  # "@" pairs (4.4)
            line_ctx = replace(ctx, extra={**ctx.extra, LINE_PAIRS: pairs}) if pairs else ctx
            if arrivals:
                self._relay_line(line, line_ctx, arrivals)
            else:
                self._run_statements([stmt for stmt, _ in line], line_ctx)
        self.bus.poke()

    def _parse(self, text: str) -> list[ast.Line]:
        """:func:`parse`, remembering recent lines."""
        found = self._parsed.get(text)
        if found is None:
            found = self._parsed.put(text, tuple(parse(text)))
        return list(found)

    def _baud_answer(self, text: str) -> bool:
        """The line after a K20 prompt (ch. 3 K23 16 "Change Baud Rate ?? XXX kbps
        (Y/N)"): ``Y`` applies the new K20, ``N`` keeps the old one; both are consumed.
        Any other line cancels the change and runs as usual (docs/fidelity.md)."""
        asking = [m for m in self.motors.values() if m.pending_baud is not None]
        if not asking:
            return False
        answer = text.strip().upper()
        for motor in asking:
            motor.answer_baud(answer == "Y")
        return answer in ("Y", "N")

    def _run_statements(self, statements: list[ast.Statement], ctx: Context) -> None:
        if self._cut and ctx.origin in _THROUGH_ID1:
            statements = self._reachable(statements, ctx)
        for stmt in statements:
            motor_id = inner_motor(stmt) or ctx.default_motor
            motor = self.motors.get(motor_id)
            if motor is not None:
                run_statement(motor, stmt, ctx)
            else:
                self.beyond_chain(motor_id, stmt, ctx)
        end_of_line(ctx)          # an "@" of a branch left without its partner (4.4)

    def _reachable(self, statements: list[ast.Statement], ctx: Context) -> list[ast.Statement]:
        """The statements whose motor the line reaches: not one powered off or beyond a
        broken link (chain/power.py)."""
        cut = self._cut
        return [stmt for stmt in statements if (inner_motor(stmt) or ctx.default_motor) < cut]

    # -- chain timing (ch. 3 K65; .links) ----------------------------------------------
    def _arrivals(self, routed: list[list[tuple[ast.Statement, int]]],
                  nbytes: int) -> dict[int, int]:
        """When the host line's text reaches each motor it addresses (and those between)."""
        last = max((min(mid, len(self.motors)) for line in routed for _, mid in line),
                   default=1)
        arrivals = {1: self.kernel.now}
        for motor_id in range(2, last + 1):
            arrivals[motor_id] = self.links.arrival(motor_id - 1, motor_id, nbytes,
                                                    arrivals[motor_id - 1])
        return arrivals

    def _relay_line(self, line: list[tuple[ast.Statement, int]], ctx: Context,
                    arrivals: dict[int, int]) -> None:
        """Each motor runs its statements of the line when the line reaches it."""
        groups: dict[int, list[ast.Statement]] = {}
        for stmt, motor_id in line:
            groups.setdefault(min(motor_id, len(self.motors)), []).append(stmt)
        now = self.kernel.now
        for hop_id in sorted(groups):
            statements = groups[hop_id]
            at = arrivals.get(hop_id, now)
            if at <= now:
                self._run_statements(statements, ctx)
            else:
                self.kernel.schedule_at(at, partial(self._relayed, statements, ctx),
                                        priority=PRIO_IO, name="chain-relay")

    def _relayed(self, statements: list[ast.Statement], ctx: Context) -> None:
        self._run_statements(statements, ctx)
        self.bus.poke()
        self._changed()

    def _k65_written(self, value: int) -> None:
        """K65 written on ID1 is written on every motor (ch. 3 K65)."""
        for motor in self.motors.values():
            if motor.id != 1:
                motor.params.set(65, value)

    # -- chain-wide commands and banks (cml-users-guide.txt 2.1.2) ------------
    def chain_command(self, motor: MotorCore, stmt: ast.Exec, ctx: Context) -> None:
        """Commands that act on the whole chain: ``]``, ``]1``, ``*``, ``*1``, ``}``, ``>``,
        ``<``."""
        op = stmt.op
        reached = self._reached(ctx)
        if op == "pause":          # 2.1.2 "]": stop all motors, pause the banks
            for each in reached:
                each.program.pause()
            for each in reached:
                each.stop()
        elif op == "pause_motor":
            motor.stop()
        elif op == "estop":
            for each in reached:
                each.emergency_stop()
                each.program.emergency()
        elif op == "estop_release":
            for each in reached:
                each.emergency_release()
            for each in reached:
                if not each.estopped:
                    each.program.emergency_released()
        elif op == "stop_after_line":
            motor.program.stop_after_line()
        elif op == "next_line":
            motor.program.next_line(ctx)
        elif op == "prev_line":
            motor.program.prev_line(ctx)

    def _reached(self, ctx: Context) -> list[Motor]:
        """The motors a chain-wide command of ``ctx`` reaches: all of them, but those
        cut off from ID1 for a line that travels the chain (chain/power.py)."""
        cut = self._cut if ctx.origin in _THROUGH_ID1 else 0
        return [m for m in self.motors.values() if not cut or m.id < cut]

    def bank_command(self, motor: MotorCore, stmt: ast.Statement, ctx: Context) -> None:
        """Bank execution commands: ``[`` ``]L`` ``B100`` ... (6.5; RT3 2.3, 3.2)."""
        if isinstance(stmt, ast.StartBank):
            if stmt.kind == "B":
                if stmt.index is None:
                    motor.program.resume()
                else:
                    motor.program.start(stmt.index, ctx)
                return
            runner = motor.logic_motion if stmt.kind == "LM" else motor.ladder
            if stmt.index is None:
                runner.resume()
            else:
                runner.start(stmt.index, ctx)
        elif isinstance(stmt, ast.StopBank):
            (motor.logic_motion if stmt.kind == "LM" else motor.ladder).pause()
        elif isinstance(stmt, ast.ClearBanks):
            if stmt.ladder:
                motor.ladder.stop()
                motor.logic_motion.stop()
            else:
                motor.program.terminate()
            motor.banks.clear(stmt.ladder)
        # C J CL JL X X- W END typed outside a bank mean nothing in direct mode

    def bank_query(self, motor: MotorCore, query: ast.Query) -> list[str] | None:
        """Bank listings ``?#``, ``?L#``, ``?1000`` (6.6); error05/06 for a missing bank."""
        if query.number is None:
            return None
        if query.letter is None and query.number == 1000:
            listing: list[str] = motor.banks.all_listing(motor.id)
            return listing
        ladder = query.letter == "L"
        if not 1 <= query.number <= motor.banks.count(ladder):
            return None
        lines: list[str] | None = motor.banks.listing(ladder, query.number)
        if lines is None:
            raise NoLadderBankError() if ladder else NoProgramBankError()
        return lines

    # -- saving ---------------------------------------------------------------
    def save(self, motor: int) -> None:
        """``$``: store parameters, data and banks of motor ``motor`` (2.1.2)."""
        found = self.bus.require(motor)
        if self.store is not None:
            self.store.save_snapshot(motor, found.to_snapshot())
        else:
            self._saved[motor] = found.to_snapshot()

    def _restore(self) -> None:
        for motor in self.motors.values():
            if self.store is not None:
                saved = self.store.load(motor.id)   # shape checked: StoreError names it
                problem = snapshot_problem(saved) if saved else ""
                if problem:
                    raise StoreError(bad_state_message(self.store.path, motor.id, problem))
                if saved:
                    try:
                        motor.load_snapshot(saved)
                    except (ValueError, TypeError, KeyError, AttributeError) as exc:
                        raise StoreError(bad_state_message(
                            self.store.path, motor.id, f"cannot be restored ({exc})")) from exc
                motor.params.on_change(
                    partial(self._store_param, motor.id))

    def _store_param(self, motor_id: int, k: int, old: int, value: int) -> None:
        """Persist an accepted K change (ch. 3); a failed write is told, never raised:
        the value holds in memory until the next power cycle."""
        del old
        if self.store is None:
            return
        try:
            self.store.save_param(motor_id, k, value)
        except StoreError as exc:
            log.warning("K%d.%d=%d not stored: %s", k, motor_id, value, exc)
            self.bus.emit(motor_id, "message", f"K{k}.{motor_id} not stored: {exc}")

    def close(self) -> None:
        """Close the store (unsaved data is lost, as at power off)."""
        if self.store is not None:
            self.store.close()

    # -- Modbus (5.6): COM0 slave mode, COM1 host, see coolmuscle.chain.firmware_modbus --
    def _attach_modbus(self) -> None:
        from .firmware_modbus import Com1Port, ModbusSlave, RtuSlaveLine
        self.modbus = ModbusSlave(self)
        self.modbus_line = RtuSlaveLine(self, self.modbus)
        self.host_line.mode = self.modbus_line
        self.motors[1].params.on_change(
            lambda k, _old, _new: self.modbus_line.k81_written() if k == 81 else None)
        self.com1 = Com1Port(self, self.bus.emit)

    def beyond_chain(self, motor_id: int, stmt: ast.Statement, ctx: Context) -> bool:
        """A statement for an ID not on the chain (also from banks): the COM1 Modbus
        slave takes it when it is "final ID + 1" (5.6.6); else it goes unanswered."""
        if not self.com1.serves(motor_id):
            return False
        self._com1_statement(stmt, ctx)
        return True

    def _com1_statement(self, stmt: ast.Statement, ctx: Context) -> None:
        """A statement for the COM1 Modbus slave, "final ID + 1" (5.6.6, 5.6.7)."""
        origin, io = ctx.origin, self.com1.io_id
        if isinstance(stmt, ast.Query) and stmt.letter is None and stmt.number in (50, 70):
            if stmt.number == 50:
                self.com1.read_outputs(origin)
            else:
                self.com1.read_inputs(origin)
        elif isinstance(stmt, ast.Output):
            if 1 <= stmt.index <= 16:
                self.com1.write_output(stmt.index, stmt.on, origin)
            else:
                self._com1_error(io, ctx)
        elif isinstance(stmt, ast.OutputWord):
            word = evaluate(stmt.value, MotorEval(self.motors[self.com1.final_motor]))
            if 0 <= word <= 0xFFFF:
                self.com1.write_outputs(word, origin)
            else:
                self._com1_error(io, ctx)

    def _com1_error(self, io: int, ctx: Context) -> None:
        final = self.motors[self.com1.final_motor]
        if final.reports(Report.MESSAGES):
            text = OutOfRangeError().motor_line(io)
            if ctx.replies is not None:
                ctx.replies.append(text)
            self.bus.emit(io, "message", text, origin=ctx.origin)

    # -- device API: data -------------------------------------------------------
    def get_param(self, motor: int, k: int) -> int:
        return self.bus.get_param(motor, k)

    def set_param(self, motor: int, k: int, value: int) -> None:
        self.bus.require(motor).params.set(k, value)

    def get_register(self, motor: int, kind: str, index: int) -> int | str:
        from ..motor.programs.queries import format_value
        value = self.bus.require(motor).memory.get(kind, index)
        if isinstance(value, VNumber):
            return value.value
        return int(value) if isinstance(value, int) else format_value(value)

    def register_value(self, motor: int, kind: str, index: int) -> int:
        """The number the motor computes with: V strings packed, V states read live."""
        m = self.bus.require(motor)
        return m.register_number(ast.Reg(kind.upper(), index, None))

    def set_register(self, motor: int, kind: str, index: int, value: int | str) -> None:
        self.bus.require(motor).write_register(kind, index, value)

    # -- device API: live values --------------------------------------------------
    def snapshot(self, motor: int) -> MotorSnapshot:
        m = self.bus.require(motor)
        target = m.axis.target()
        position, error, torque = m.axis.position(), m.axis.position_error(), m.torque_exact()
        return MotorSnapshot(
            motor=m.id, time=self.kernel.now, position=round(position),
            target=round(target) if abs(target) != float("inf") else 0,
            position_error=round(error), speed=m.speed_units(),
            speed_pps=m.axis.velocity(), torque=round(torque), status=m.status,
            inputs=m.io.input_word(), outputs=m.io.output_word(),
            temperature=m.temperature, voltage=m.voltage, analog=m.analog,
            encoder_count=m.encoder_count, enabled=m.axis.enabled,
            position_exact=position, position_error_exact=error, torque_exact=torque,
            extra={"analog_output": m.analog_output(),   # K35 (Modbus K78+54)
                   "origin_search": int(m.origin.active),  # 5.3 running (fieldbus homing)
                   "origin_done": int(m.origin_done)})     # 5.3 completed since the last |

    def cyclic_state(self, motor: int) -> CyclicState:
        return self.bus.cyclic_state(motor)

    def machine_data(self, motor: int) -> dict[str, float]:
        """The load and drive data ``motor`` runs with, by machine-file key."""
        from .machine import DRIVE_KEYS, LOAD_KEYS
        plant = self.bus.require(motor).plant
        return {key: float(getattr(plant, attr))
                for key, attr in {**LOAD_KEYS, **DRIVE_KEYS}.items()}

    # -- device API: signals and faults -------------------------------------------
    def set_input(self, motor: int, number: int, on: bool) -> None:
        self.bus.require(motor).set_input_level(number, on)
        self._changed()

    def set_analog(self, motor: int, counts: int) -> None:
        if not 0 <= counts <= 1023:
            raise OutOfRangeError("analog input is 0..1023 (6.6 ?74)")
        self.bus.require(motor).analog = counts

    def target_stream(self, motor: int, period_ns: int = 0) -> TargetStream:
        return MotorStream(self.bus.require(motor), period_ns)

    def inject_fault(self, motor: int, fault: str, **params: object) -> None:
        self.bus.require(motor).inject_fault(fault, **params)
        self._changed()

    # -- device API: wire faults (docs/wire-faults.md) -------------------------------------
    def inject_wire_fault(self, door: str, kind: str, *, at: float = 0.0,
                          until: float | None = None, every: int | None = None,
                          probability: float | None = None, seed: int | None = None,
                          count: int | None = None, motor: int | None = None,
                          **params: object) -> int:
        """Install a wire fault ``at`` seconds from now (until ``until`` s from now);
        returns its number.  ``ValueError`` for an unknown door, kind or parameter."""
        schedule = {"at": at, "until": until, "every": every, "probability": probability,
                    "seed": seed, "count": count, "motor": motor}
        return self.add_wire_fault(wire_fault(
            door, kind, {k: v for k, v in schedule.items() if v is not None}, params))

    def add_wire_fault(self, fault: WireFault) -> int:
        """Install a checked :class:`~coolmuscle.device.wire.schedule.WireFault` (the
        machine file's ``[[wire.fault]]``); returns its number."""
        if fault.motor is not None:
            self.bus.require(fault.motor)
            if fault.kind == "link_break" and fault.motor >= len(self.motors):
                raise ValueError(f"link_break: motor {fault.motor} is the last on the "
                                 f"chain; its COM1 has no link to another motor")
        if fault.door in ("host-line", "chain") and self.host_line.wire is None:
            self.host_line.wire = LineFaults(self.kernel, self.wire_faults,
                                             self.host_line.hand_out)
        return self.wire_faults.add(fault).id

    def clear_wire_faults(self, fault: int | None = None, *, door: str | None = None) -> int:
        """End wire faults: number ``fault``, those of ``door``, or all; how many ended."""
        return self.wire_faults.clear(fault, door)

    def _saved_state(self, motor: int) -> dict[str, object] | None:
        """What a power cycle of ``motor`` brings back: the store's snapshot (or what
        ``$`` saved in this run without a store)."""
        if self.store is None:
            return self._saved.get(motor)
        try:
            return self.store.load(motor)
        except StoreError as exc:
            log.warning("motor %d powers up without its saved data: %s", motor, exc)
            return None

    def _wire_record(self, record: WireRecord) -> None:
        """Every wire fault's doing is an event (kind ``wire``), for the trace, the
        transcript and the web page; never printed on the host line."""
        self.bus.emit(record.motor or 0, "wire", record.line(), origin="api")

    def _chain_fault(self, fault: ActiveFault, on: bool) -> None:
        """A ``chain`` fault begins or ends: who is cut off; a motor powered off or on."""
        self._cut = self.bus.cut_from = cut_from(self.wire_faults)
        motor = self.motors.get(fault.motor or 0)
        if fault.kind != "power_off" or motor is None:
            return
        if on:
            power_off(motor)
        elif self.wire_faults.lasting("chain", "power_off", motor.id) is None:
            power_on_again(motor, self._saved_state(motor.id))
        self.bus.poke()
        self._changed()

    # -- device API: events, observers and traces ---------------------------------
    def subscribe(self, listener: EventListener) -> Callable[[], None]:
        return self.bus.subscribe(listener)

    def trace_feed(self) -> TraceFeed:
        """Record every motor from now on (:class:`coolmuscle.device.trace.TraceFeed`)."""
        from ..device.trace import TraceFeed  # traces are optional: loaded when used
        return TraceFeed(self.kernel, self.motors, self.observe, self.wire_faults)

    # -- device API: Modbus (5.6) -------------------------------------------------
    def modbus_request(self, unit: int, pdu: bytes, *, tcp: bool = False) -> bytes | None:
        return self.modbus.handle(unit, pdu, tcp=tcp)

    def modbus_station(self) -> int:
        return self.modbus_line.station() if self.modbus_line.active() else 0


if TYPE_CHECKING:
    def _meets_its_protocols(chain: Chain) -> tuple[Device, ChainCommands, MotorBus]:
        """For mypy (tests/test_quality.py): a chain is the device API
        (``device.api.Device``) and the chain-wide commands of its bus, which is the bus
        of its motors (``motor.core.MotorBus``)."""
        return chain, chain, chain.bus


__all__ = ["Chain", "VState", "MotorError"]
