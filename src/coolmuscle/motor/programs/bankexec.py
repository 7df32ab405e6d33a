"""What program and ladder banks share: resumable execution on kernel events, and statements.

A bank line runs as a Python generator that *yields* what it waits for: a time
(:class:`Sleep`: ``T#``), motions to be in position (:class:`MotionWait`: program lines,
2.2.2 "P"), or a condition to turn false (:class:`Watch`: ``W#``, 4.2.4).  The
:class:`Runner` resumes it from kernel events only: a timer, or a chain "poke" (an input
edge, a host line, a motion milestone, the end of a ladder scan ...).  Nothing polls.

The statements whose meaning is the same in both kinds of banks (assignments, outputs,
queries, execution commands, branch conditions) are dispatched here to
:mod:`.direct` on the motor the statement names (6.5 "P"/"L" columns).
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ...cml import ast
from ...cml.ast import inner_motor
from ...errors import MotorError, OutOfRangeError
from ...sim.kernel import NS_PER_MS, PRIO_LOGIC, Timer
from .banks import Bank, condition_only
from .direct import MotorEval, route

if TYPE_CHECKING:
    from ..context import Context
    from ..core import MotorCore

#: RT3 3.4 "Typically steps take 250 µs to execute".
STEP_NS = 250_000


@dataclass(init=False, unsafe_hash=True, slots=True)
class Sleep:
    """Resume after ``ns`` nanoseconds (``T#``)."""

    ns: int

    def __init__(self, ns: int) -> None:
        # written out: built on the hot path (docs/architecture.md "Fast code")
        self.ns = ns


@dataclass(init=False, unsafe_hash=True, slots=True)
class MotionWait:
    """Resume when every motor in ``motors`` has finished its motion (in position)."""

    motors: tuple[MotorCore, ...]

    def __init__(self, motors: tuple[MotorCore, ...]) -> None:
        # written out: built on the hot path (docs/architecture.md "Fast code")
        self.motors = motors


@dataclass(frozen=True, slots=True)
class Hold:
    """Stay where you are until :meth:`Runner.rearm` (the bank was paused by one of its
    own statements, e.g. ``]``)."""


HOLD = Hold()


@dataclass(init=False, unsafe_hash=True, slots=True)
class Watch:
    """``W#``: resume with ``False`` once ``holds()`` is false, ``True`` at the timeout."""

    holds: Callable[[], bool]
    timeout_ns: int | None

    def __init__(self, holds: Callable[[], bool], timeout_ns: int | None) -> None:
        # written out: built on the hot path (docs/architecture.md "Fast code")
        self.holds = holds
        self.timeout_ns = timeout_ns


Request = Sleep | MotionWait | Watch | Hold
LineGen = Generator[Request, object, object]


class Runner:
    """Drives one generator of wait requests with kernel events; can halt and re-arm."""

    def __init__(self, motor: MotorCore, on_done: Callable[[object], None]) -> None:
        self.motor = motor
        self.kernel = motor.kernel
        self._on_done = on_done
        self.gen: LineGen | None = None
        self._request: Request | None = None
        self._timer: Timer | None = None
        self._unwatch: Callable[[], None] | None = None
        self._deadline: int | None = None
        self._left: int | None = None   # time left of a halted Sleep/Watch
        self._token = 0
        self.executing = False           # inside gen.send(): statements are running
        self._drop = False               # abandoned while executing: close at its next yield

    @property
    def busy(self) -> bool:
        """A generator is in progress (running or halted in a wait)."""
        return self.gen is not None

    def run(self, gen: LineGen) -> None:
        """Start ``gen`` now."""
        self.abandon()
        self.gen = gen
        self._resume(None)

    def abandon(self) -> None:
        """Drop the generator (``*``, stop, a new start)."""
        self._disarm()
        if self.executing:
            self._drop = True
            return
        gen, self.gen, self._request = self.gen, None, None
        if gen is not None:
            gen.close()

    def halt(self) -> None:
        """Stop waiting but keep the generator (pause); :meth:`rearm` continues it."""
        if self._deadline is not None:
            self._left = max(self._deadline - self.kernel.now, 0)
        self._disarm()

    def rearm(self) -> None:
        """Continue a halted generator: wait again for what it was waiting for."""
        if self.gen is None:
            return
        if self._request is None or isinstance(self._request, Hold):
            self._resume(None)
            return
        self._arm(self._request, self._left)

    # -- internals ------------------------------------------------------------
    def _disarm(self) -> None:
        self._token += 1
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._unwatch is not None:
            self._unwatch()
            self._unwatch = None
        self._deadline = None

    def _resume(self, value: object) -> None:
        self._disarm()
        self._left = None
        gen = self.gen
        if gen is None:
            return
        self.executing = True
        try:
            request = gen.send(value)
        except StopIteration as stop:
            self.executing = False
            if self.gen is gen:
                self.gen, self._request = None, None
                if self._drop:
                    self._drop = False
                else:
                    self._on_done(stop.value)
            return
        except BaseException:
            self.executing = False
            self.gen, self._request, self._drop = None, None, False
            raise
        self.executing = False
        if self._drop:
            self._drop = False
            self.gen, self._request = None, None
            gen.close()
            return
        if self.gen is gen:
            self._request = request
            self._arm(request, None)

    def _later(self, value: object) -> Callable[[], None]:
        token = self._token

        def fire() -> None:
            if token == self._token:
                self._resume(value)
        return fire

    def _arm(self, request: Request, left: int | None) -> None:
        self._disarm()
        if isinstance(request, Hold):
            return
        if isinstance(request, Sleep):
            ns = request.ns if left is None else left
            self._deadline = self.kernel.now + ns
            self._timer = self.kernel.schedule(ns, self._later(None), priority=PRIO_LOGIC,
                                               name="bank-timer")
        elif isinstance(request, MotionWait):
            self._arm_motion(request)
        else:
            self._arm_watch(request, left)

    def _arm_motion(self, request: MotionWait) -> None:
        fire = self._later(None)

        def check() -> None:
            for motor in request.motors:
                if not motor.motion_done():
                    return
            self._cancel_watch()
            self.kernel.call_soon(fire, priority=PRIO_LOGIC, name="bank-in-position")
        self._unwatch = self.motor.bus.watch(check, [m.id for m in request.motors])
        check()

    def _arm_watch(self, request: Watch, left: int | None) -> None:
        timeout = request.timeout_ns if left is None else left
        if timeout is not None:
            self._deadline = self.kernel.now + timeout
            self._timer = self.kernel.schedule(timeout, self._later(True),
                                               priority=PRIO_LOGIC, name="bank-wait")
        fire = self._later(False)

        def check() -> None:
            if not request.holds():
                self._cancel_watch()
                self.kernel.call_soon(fire, priority=PRIO_LOGIC, name="bank-wait-end")
        self._unwatch = self.motor.bus.watch(check)
        check()

    def _cancel_watch(self) -> None:
        if self._unwatch is not None:
            self._unwatch()
            self._unwatch = None


# ---------------------------------------------------------------- statements

def target_motor(motor: MotorCore, stmt: ast.Statement) -> MotorCore | None:
    """The motor a statement addresses (its ``.n``), ``None`` when not on the chain."""
    motor_id = inner_motor(stmt)
    if motor_id is None or motor_id == motor.id:
        return motor
    return motor.bus.motor(motor_id)


def run_plain(motor: MotorCore, stmt: ast.Statement, ctx: Context) -> None:
    """A statement that means the same in direct mode and in banks (6.5), on its motor
    (an ID past the chain goes to the chain: the COM1 device, or nobody)."""
    route(motor, stmt, ctx)


def holds(motor: MotorCore, condition: ast.Expr) -> bool:
    """Truth of a branch condition on ``motor`` (V alone means V > 0, 6.3 "V")."""
    from .evaluate import condition as truth
    try:
        return truth(condition, MotorEval(motor))
    except (MotorError, LookupError, ValueError, ArithmeticError):
        return False


def timer_ns(motor: MotorCore, reg: ast.Reg) -> int:
    """T# of the motor the register names, in ns (2.2.1 "T": msec, 0 = no action)."""
    target = (motor if reg.motor is None or reg.motor == motor.id
              else motor.bus.motor(reg.motor))
    if target is None:
        return 0
    try:
        return max(int(target.register_number(reg)), 0) * NS_PER_MS
    except (MotorError, LookupError, ValueError):
        target.report_error(None, OutOfRangeError())
        return 0


def wait_branch(motor: MotorCore, branch: ast.Branch, wait: ast.Wait) -> Watch:
    """``cond, W#, else``: wait while ``cond`` holds, up to T# (W0 forever) (4.2.4)."""
    ns = timer_ns(motor, ast.Reg("T", wait.index, wait.motor))
    return Watch(lambda: holds(motor, branch.condition), ns or None)


# ---------------------------------------------------------------- units

@dataclass(unsafe_hash=True, slots=True)
class Unit:
    """What runs as one line: a stored line, or lines joined by ``;`` (2.2.2 ";")."""

    statements: tuple[ast.Statement, ...]
    quiet: bool      # ladder: the line ends with ";", results are not displayed
    first: int       # index of its first stored line
    last: int        # index of its last stored line (lines joined to the first)


#: Told when a unit of a bank starts: ``(bank, first, last)``, the indexes of the
#: unit's first and last stored line.  Off (``None``) unless someone observes the
#: bank lines run (the test plug-in's bank coverage, docs/testing-your-project.md).
LineObserver = Callable[[int, int, int], None]


def _merge_condition(cond: ast.Line, line: ast.Line) -> ast.Line:
    """``V2.1>V3.1;`` + ``V2.1=V3.1, T0.1`` is ``V2.1>V3.1, V2.1=V3.1, T0.1`` (6.4 ";")."""
    branch = cond.statements[0]
    assert isinstance(branch, ast.Branch)
    stmts = line.statements
    merged = ast.Branch(branch.condition, stmts[:1], stmts[1:2])
    return ast.Line((merged,), line.joined, line.source)


def _flow(line: ast.Line) -> bool:
    return any(isinstance(s, (ast.Call, ast.Loop, ast.LoopEnd)) for s in line.statements)


def merged_lines(bank: Bank) -> list[tuple[int, int, ast.Line]]:
    """Stored lines with each condition-only line merged into the line after it:
    (index of the first stored line, of the last, the line)."""
    out: list[tuple[int, int, ast.Line]] = []
    pending: tuple[int, ast.Line] | None = None
    for index, line in enumerate(bank):
        if pending is not None:
            out.append((pending[0], index, _merge_condition(pending[1], line)))
            pending = None
        elif condition_only(line):
            pending = (index, line)
        else:
            out.append((index, index, line))
    if pending is not None:
        out.append((pending[0], pending[0],
                    ast.Line(pending[1].statements, False, pending[1].source)))
    return out


def program_units(bank: Bank) -> list[Unit]:
    """Program bank: lines joined by ``;`` run as one line; C J X X- end a unit."""
    units: list[Unit] = []
    statements: list[ast.Statement] = []
    first = 0
    last = 0
    for index, end, line in merged_lines(bank):
        if not statements:
            first = index
        last = end
        statements.extend(line.statements)
        if not line.joined or _flow(line):
            units.append(Unit(tuple(statements), False, first, last))
            statements = []
    if statements:
        units.append(Unit(tuple(statements), False, first, last))
    return units


def ladder_units(bank: Bank, displays: bool = True) -> list[Unit]:
    """Ladder bank: every line on its own; ``;`` only silences its results (RT3 1.1).
    ``displays=False`` (CM2): assignments never display (docs/fidelity.md)."""
    return [Unit(line.statements, line.joined or not displays, index, end)
            for index, end, line in merged_lines(bank)]
