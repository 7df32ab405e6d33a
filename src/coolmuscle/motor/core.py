"""What the parts of a motor see of it: :class:`MotorCore`, implemented by :class:`.motor.Motor`.

The sub-packages (programs, signals, supervision) are handed the motor they work for
and type it with this protocol, never with the façade class: the façade imports them,
so they must not import it back (docs/architecture.md).  The few members whose classes
live in those sub-packages are typed with the narrow protocols below.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any, Protocol

from ..cml import ast
from ..errors import MotorError
from ..sim.kernel import Kernel
from .context import Context
from .motion.axis import Axis
from .motion.planner import Limits
from .motion.plant import Plant
from .motion.profile import Profile
from .motion.trajectory import Timeline
from .signals.io import DigitalIO
from .state.firmware import Firmware
from .state.memory import Memory, VNumber, VState, VString
from .state.param_table import ParamTable
from .state.units import Resolution
from .status import Report
from .supervision.thermal import Thermal


class MotorBus(Protocol):
    """What a motor needs from its chain."""

    def emit(self, motor: int, kind: str, text: str, value: int | None = None,
             origin: str = "motor") -> None:
        """Report a line (host line + event stream)."""

    def motor(self, motor_id: int) -> MotorCore | None:
        """Another motor of the chain (None when absent)."""

    def watch(self, callback: Callable[[], None],
              motors: Iterable[int] | None = None) -> Callable[[], None]:
        """Call ``callback`` at every poke (about ``motors``) until the remover is called."""

    def poke(self, motor: int | None = None) -> None:
        """Something changed (input, data, motion of ``motor``): re-check the bank waits."""

    def chain_command(self, motor: MotorCore, stmt: ast.Exec, ctx: Context) -> None:
        """Chain-wide execution commands (``]``, ``*``, ``*1`` ...)."""

    def bank_command(self, motor: MotorCore, stmt: ast.Statement, ctx: Context) -> None:
        """Bank execution commands: ``[`` ``]L`` ``B100`` ... (6.5; RT3 2.3, 3.2)."""

    def bank_query(self, motor: MotorCore, query: ast.Query) -> list[str] | None:
        """Bank listings ``?#``, ``?L#``, ``?1000`` (6.6)."""

    def relay(self, src: int, dst: int, nbytes: int) -> int:
        """When ``nbytes`` that ID ``src`` sends now reach ID ``dst`` (ch. 3 K65)."""

    def save(self, motor: int) -> None:
        """``$``: store parameters, data and banks of motor ``motor`` (2.1.2)."""

    def beyond_chain(self, motor_id: int, stmt: ast.Statement, ctx: Context) -> bool:
        """A statement for an ID not on the chain (the COM1 Modbus slave, 5.6.6)."""


class BankRunner(Protocol):
    """A ladder or logic motion runner (:class:`.programs.ladder.LadderRunner`)."""

    def start(self, number: int, ctx: Context | None = None) -> None: ...

    def pause(self) -> None: ...

    def resume(self) -> None: ...

    def stop(self) -> None: ...


class ProgramRunner(Protocol):
    """The program bank executor (:class:`.programs.program.ProgramExecutor`)."""

    state: str
    sel_s: int
    sel_a: int
    sel_path: Any                   # .programs.coordinated.Selection

    def start(self, number: int, ctx: Context | None = None) -> None: ...

    def pause(self) -> None: ...

    def resume(self) -> None: ...

    def next_line(self, ctx: Context | None = None) -> None: ...

    def prev_line(self, ctx: Context | None = None) -> None: ...

    def stop_after_line(self) -> None: ...

    def terminate(self) -> None: ...

    def emergency(self) -> None: ...

    def emergency_released(self) -> None: ...


class InputFunctionsView(Protocol):
    """The input functions (:class:`.signals.inputs.InputFunctions`)."""

    def ladder_held(self) -> bool: ...


class OriginSearchView(Protocol):
    """The origin search (:class:`.supervision.origin.OriginSearch`)."""

    def on_limit(self, direction: int) -> bool: ...


class MotorCore(Protocol):
    """The motor as its sub-systems see it (members of :class:`.motor.Motor`)."""

    # -- identity, time and state (ch. 3, 6.1, 6.2)
    id: int
    kernel: Kernel
    firmware: Firmware
    bus: MotorBus
    params: ParamTable
    memory: Memory
    io: DigitalIO
    plant: Plant
    axis: Axis
    timeline: Timeline
    thermal: Thermal
    alarm: int
    estopped: bool      # ``*`` until ``*1`` (2.1.2)
    voltage: int
    origin_done: bool
    direct_interp_kind: str
    banks: Any                      # .programs.banks.BankStore
    path: Any                       # .programs.coordinated.PairMotion | None

    # -- sub-systems built by the façade (read-only here)
    @property
    def program(self) -> ProgramRunner: ...

    @property
    def ladder(self) -> BankRunner: ...

    @property
    def logic_motion(self) -> BankRunner: ...

    @property
    def inputs(self) -> InputFunctionsView: ...

    @property
    def origin(self) -> OriginSearchView: ...

    def k(self, number: int) -> int: ...

    @property
    def resolution(self) -> Resolution: ...

    def reports(self, flag: Report) -> bool: ...

    # -- live values (6.6)
    @property
    def status(self) -> int: ...

    def position(self) -> int: ...

    def speed_units(self) -> int: ...

    def torque(self) -> int: ...

    @property
    def temperature(self) -> int: ...

    @property
    def analog(self) -> int: ...

    @property
    def encoder_count(self) -> int: ...

    def z_position(self) -> float: ...

    def position_error_exempt(self) -> bool: ...

    def motion_done(self) -> bool: ...

    def select_torque_limit(self, percent: int) -> None: ...

    # -- what the motor says (6.6, K23)
    def say(self, ctx: Context | None, text: str, kind: str = "reply",
            value: int | None = None) -> None: ...

    def report_error(self, ctx: Context | None, error: MotorError) -> None: ...

    def report_status(self) -> None: ...

    # -- data (6.2)
    def register_number(self, reg: ast.Reg) -> int: ...

    def write_register(self, kind: str, index: int,
                       value: int | str | VState | VString) -> None: ...

    def state_value(self, name: str) -> int: ...

    def v_numeric(self, value: VNumber | VString | VState) -> int: ...

    def write_state(self, name: str, value: int) -> None: ...

    def propose_baud(self, ctx: Context | None, value: int) -> None: ...

    # -- motion (4.1, 4.4, 5.1, 5.3)
    def can_move(self) -> bool: ...

    def limits(self, s_value: int, a_value: int,
               decel_a: int | None = None) -> Limits | None: ...

    def move_to(self, waypoints: Sequence[tuple[float, Limits | None]],
                delay_ns: int = 0) -> None: ...

    def run_continuous(self, s_value: int, limits: Limits | None) -> None: ...

    def follow(self, target: float) -> None: ...

    def run_path(self, path: Any, profile: Profile, limits: Limits) -> bool: ...

    def path_end_allowed(self, user_end: float) -> bool: ...

    def direct_move(self, stmt: ast.Move) -> None: ...

    def push_to(self, target: float, limits: Limits | None,
                via: Sequence[tuple[float, Limits | None]] = ()) -> None: ...

    def push_finished(self, ux: int, reason: str) -> None: ...

    def go(self) -> None: ...

    def go_origin(self) -> None: ...

    def set_origin(self) -> None: ...

    def origin_search(self) -> None: ...

    def stop(self) -> None: ...

    def abandon_motion(self) -> None: ...

    def notify_motion_done(self, reason: str) -> None: ...

    def motion_settled(self) -> None: ...

    def jog(self, direction: int) -> None: ...

    def feed(self, direction: int) -> None: ...

    def feed_stop(self) -> None: ...

    def capture(self, index: int) -> None: ...

    # -- servo and alarms (6.5, 6.6 ?99)
    def enable(self) -> None: ...

    def free(self) -> None: ...

    def raise_alarm(self, bits: int) -> None: ...

    def reset_alarm(self) -> None: ...

    def emergency_stop(self) -> None: ...

    def emergency_release(self, *, force: bool = False) -> None: ...

    def set_temperature(self, celsius: float) -> None: ...

    # -- inputs and outputs (5.x, K26-K36)
    def set_input_level(self, number: int, on: bool) -> None: ...

    def refresh_inputs(self) -> None: ...

    def limit_sensor(self, direction: int, on: bool) -> None: ...

    def set_output(self, number: int, on: bool) -> None: ...

    def set_output_word(self, word: int) -> None: ...
