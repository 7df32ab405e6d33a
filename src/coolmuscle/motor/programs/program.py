"""The program bank executor of one motor (cml-users-guide.txt 2.2.2, 4.1-4.3; RT3 §2).

``[#.n`` starts bank # of motor n.  Lines run one at a time; a line starts its motions
(on any motor of the chain, 4.3.1) and the next line waits until every motion it
started with ``P``/``Q`` is in position (``Y``/``Z`` do not make it wait, 4.3.2).
Several ``P`` of one motor in a line, or in lines joined by ``;``, are one merge motion
(4.1.2); ``S``/``A`` select the data of the motions after them, a second ``A`` on the
line is the deceleration (4.1.3).  ``C`` calls (10 levels, no recursion), ``J`` jumps,
``X``/``X-`` loop (10 levels; ``X0`` forever; no ``X-`` loops to the end), branches
pick their actions, ``T`` and ``W`` wait on timers and conditions (4.2.4).

Host control (2.1.2, 6.5): ``[`` resumes, ``]`` pauses (twice: stops), ``}`` stops after
the line (twice: stops), ``>``/``<`` step a paused bank (``End.n``, ``Can't back!``),
``*`` abandons the line until ``*1`` resumes with the next one (``*`` twice: stops).
Everything happens on kernel events; a line takes at least its steps x 250 µs, so no
bank can loop in zero time.  The motion model is in :mod:`.motor` / :mod:`.planner`.
"""

from __future__ import annotations

from collections.abc import Generator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ...cml import ast
from ...errors import MotorError, NoProgramBankError, OutOfRangeError
from ...sim.kernel import PRIO_LOGIC, Timer
from ..core import MotorCore  # imported at run time: the compiled dataclasses need it
from ..motion.planner import Limits
from ..motion.profile import Profile
from ..state import units as units_mod
from .bankcheck import expr_steps, statement_steps
from .bankexec import (
    HOLD,
    STEP_NS,
    LineGen,
    LineObserver,
    MotionWait,
    Request,
    Runner,
    Sleep,
    Unit,
    holds,
    program_units,
    run_plain,
    target_motor,
    timer_ns,
    wait_branch,
)
from .coordinated import LinePaths, PairMotion, Selection, message_bytes, report_leftovers, request
from .queries import display_reply

if TYPE_CHECKING:
    from ..context import Context

IDLE, RUNNING, PAUSED, STEPPING, ESTOP = "idle", "running", "paused", "stepping", "estop"
MAX_CALL_DEPTH = 10   # 2.2.2 "C": "The maximum layer (nesting) should be under 10"
MAX_LOOP_DEPTH = 10   # 2.2.2 "X": "The repeatable layer (nesting) is up to 10"
CANCELLED = object()
_MOTION_EXECS = frozenset({"origin", "go_origin", "go"})
Step = Generator[Request, object, object]
Steps = Generator[Request, object, None]    # a statement that never ends the line


@dataclass(slots=True)
class Frame:
    """One bank on the call stack: its units, the next unit, open loops, the last run."""

    bank: int
    units: list[Unit]
    pc: int = 0
    loops: list[list[int]] = field(default_factory=list)     # [start, remaining or -1]
    last: int | None = None


@dataclass(init=False, slots=True)
class _Motion:
    """The motion a line gives one motor: waypoints (merge), push, whether the line waits."""

    motor: MotorCore
    waypoints: list[tuple[float, Limits | None]]
    issued_at: int
    push: bool
    wait: bool
    continuous: tuple[int, Limits | None] | None
    remaining: list[tuple[float, Limits | None]] | None  # what a pause interrupted
    profile: Profile | None                     # the plan that was issued
    path: PairMotion | None                     # an interpolation (4.4)
    delay: int               # ns until the command reaches the motor (K65 chain timing)

    def __init__(self, motor: MotorCore,
                 waypoints: list[tuple[float, Limits | None]] | None = None,
                 issued_at: int = -1, push: bool = False, wait: bool = True,
                 continuous: tuple[int, Limits | None] | None = None,
                 remaining: list[tuple[float, Limits | None]] | None = None,
                 profile: Profile | None = None, path: PairMotion | None = None,
                 delay: int = 0) -> None:
        # written out: built on the hot path (docs/architecture.md "Fast code")
        self.motor = motor
        self.waypoints = [] if waypoints is None else waypoints
        self.issued_at = issued_at
        self.push = push
        self.wait = wait
        self.continuous = continuous
        self.remaining = remaining
        self.profile = profile
        self.path = path
        self.delay = delay


@dataclass(init=False, slots=True)
class _Run:
    """One unit being executed."""

    frame: Frame
    index: int
    unit: Unit
    start: int
    steps: int
    motions: dict[int, _Motion]
    accel_seen: dict[int, int]
    decel: dict[int, int]
    cancelled: bool
    paths: LinePaths | None             # the "@" of this line (4.4, .coordinated)
    arrivals: dict[int, int]            # when it reaches each motor

    def __init__(self, frame: Frame, index: int, unit: Unit, start: int) -> None:
        # written out: built on the hot path (docs/architecture.md "Fast code")
        self.frame = frame
        self.index = index
        self.unit = unit
        self.start = start
        self.steps = 0
        self.motions = {}
        self.accel_seen = {}
        self.decel = {}
        self.cancelled = False
        self.paths = None
        self.arrivals = {}


class ProgramExecutor:
    """Runs the program banks of one motor."""

    def __init__(self, motor: MotorCore) -> None:
        self.motor = motor
        self.kernel = motor.kernel
        self.state = IDLE
        self.stack: list[Frame] = []
        self.runner = Runner(motor, self._unit_done)
        self.sel_s = 0          # S memory the next motion of this motor uses (2.2.2 "S")
        self.sel_a = 0          # A memory (2.2.2 "A")
        self.sel_path = Selection()   # R / N memory of the next "@" (2.2.2 "N", "R")
        self.unwaited: set[int] = set()   # motors with a Y/Z motion nobody waited for
        self._current: _Run | None = None
        self._timer: Timer | None = None
        self._stop_pending = False
        self._terminate_pending = False
        self._started: int | None = None     # the bank ``[#`` started last
        #: The bank a bare ``[`` runs from its first line: after ``*`` twice stopped it
        #: (2.1.2 "*": "Program Bank operates from the beginning with command [").
        self.restart_bank: int | None = None
        self.ctx = _bank_context(motor)
        #: Told of every line that starts (bank coverage); ``None``: nobody asks.
        self.line_observer: LineObserver | None = None

    @property
    def active(self) -> bool:
        return self.state != IDLE

    # -- host control -----------------------------------------------------------
    def start(self, number: int, ctx: Context | None = None) -> None:
        """``[#``: run bank ``number`` from its first line (error05 if it does not exist)."""
        bank = self.motor.banks.get(False, number)
        if bank is None:
            self.motor.report_error(ctx, NoProgramBankError())
            return
        if self.runner.executing:
            self.kernel.call_soon(lambda: self.start(number, ctx), priority=PRIO_LOGIC)
            return
        self.terminate()
        self.stack = [Frame(number, program_units(bank))]
        self._started = number
        self.state = RUNNING
        self._next()

    def resume(self) -> None:
        """``[``: continue a paused bank where it stopped (2.1.2 "["); after ``*`` twice
        and ``*1``, run the stopped bank again from its first line (2.1.2 "*")."""
        if self.state == IDLE and self.restart_bank is not None and not self.motor.estopped:
            self.start(self.restart_bank)
            return
        if self.state != PAUSED:
            return
        self.state = RUNNING
        self._continue()

    def pause(self) -> None:
        """``]``: pause (the motors are stopped by the chain); twice: stop (2.1.2 "]")."""
        if self.state in (PAUSED, ESTOP):
            self.terminate()
        elif self.state in (RUNNING, STEPPING):
            self._halt()
            self.state = PAUSED

    def alarm(self) -> None:
        """An alarm freed the motor: the bank pauses where it is (ch. 3 K28 function 1:
        "Re-start from paused position is possible by 6: Execute Program Bank 1")."""
        if self.state in (RUNNING, STEPPING):
            self.pause()

    def stop_after_line(self) -> None:
        """``}``: pause after the current line; twice: stop (2.1.2 "}")."""
        if self.state in (PAUSED, ESTOP):
            self.terminate()
        elif self._stop_pending:
            self._terminate_pending = True
        elif self.state in (RUNNING, STEPPING):
            self._stop_pending = True

    def emergency(self) -> None:
        """``*``: abandon the line; ``*1`` resumes with the next line; twice: stop, and
        ``[`` (after ``*1``) runs the bank from the beginning (2.1.2 "*")."""
        if self.state == ESTOP:
            started = self._started
            self.terminate()
            self.restart_bank = started
            return
        if self.state == IDLE:
            return
        self._cancel_timer()
        run = self._current
        if run is not None:
            run.cancelled = True
            self._current = None
            self.runner.abandon()
            run.frame.last, run.frame.pc = run.index, run.index + 1
        self.state = ESTOP

    def emergency_released(self) -> None:
        """``*1``: the program resumes with the next executable line (2.1.2 "*")."""
        if self.state == ESTOP:
            self.state = RUNNING
            self._next()

    def next_line(self, ctx: Context | None = None) -> None:
        """``>``: run one line of a paused bank, then pause again (2.1.2 ">")."""
        if self.state == IDLE:
            bank = self.motor.banks.get(False, 1)
            if bank is None:
                self.motor.report_error(ctx, NoProgramBankError())
                return
            self.stack = [Frame(1, program_units(bank))]
            self.state = PAUSED
        if self.state != PAUSED:
            return
        self.state = STEPPING
        if self._current is not None:
            self._continue()
        elif self._advance() is None:
            self.motor.say(ctx, f"End.{self.motor.id}")
            self.terminate()
        else:
            self._next()

    def prev_line(self, ctx: Context | None = None) -> None:
        """``<``: run the line before the last one run, then pause (``Can't back!``)."""
        frame = self.stack[-1] if self.stack else None
        target = None if frame is None or frame.last is None else frame.last - 1
        if (self.state != PAUSED or self._current is not None or frame is None
                or target is None or target < 0 or _has_flow(frame.units[target])):
            self.motor.say(ctx, "Can't back!", kind="message")
            return
        frame.pc = target
        self.state = STEPPING
        self._start_unit(frame)

    def terminate(self) -> None:
        """Stop the bank for good: ``[`` no longer resumes it."""
        self._cancel_timer()
        if self._current is not None:
            self._current.cancelled = True
        self._current = None
        self.runner.abandon()
        self.stack.clear()
        self.unwaited.clear()
        self.state = IDLE
        self._stop_pending = self._terminate_pending = False
        self.restart_bank = None

    # -- sequencing ---------------------------------------------------------------
    def _cancel_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _halt(self) -> None:
        self._cancel_timer()
        run = self._current
        if run is None:
            return
        now = self.kernel.now
        for motion in run.motions.values():
            motion.remaining = _unfinished(motion, now)
        self.runner.halt()

    def _continue(self) -> None:
        run = self._current
        if run is None:
            self._next()
            return
        resumed: set[int] = set()
        for motion in run.motions.values():
            if motion.path is not None:
                if id(motion.path) not in resumed:
                    resumed.add(id(motion.path))
                    motion.path.resume(self.kernel.now)
            elif motion.remaining:
                motion.delay = 0
                _issue(motion, motion.remaining)
            elif motion.continuous is not None:
                motion.motor.run_continuous(*motion.continuous)
            motion.remaining = None
        self.runner.rearm()

    def _advance(self) -> Frame | None:
        """The frame whose ``pc`` is the next unit to run (returns, loops), or None."""
        while self.stack:
            frame = self.stack[-1]
            if frame.pc < len(frame.units):
                return frame
            if frame.loops:
                self._loop_back(frame, len(frame.units))
                if frame.pc < len(frame.units):
                    return frame
                continue
            self.stack.pop()
        return None

    def _loop_back(self, frame: Frame, after: int) -> None:
        """``X-`` or the end of the bank: repeat the innermost loop or leave it."""
        if not frame.loops:
            frame.pc = after
            return
        loop = frame.loops[-1]
        start, remaining = loop
        if (remaining < 0 or remaining > 1) and start < after:
            if remaining > 0:
                loop[1] -= 1
            frame.pc = start
        else:
            frame.loops.pop()
            frame.pc = after

    def _next(self) -> None:
        self._timer = None
        if self.state not in (RUNNING, STEPPING):
            return
        frame = self._advance()
        if frame is None:
            self.terminate()
            return
        self._start_unit(frame)

    def _start_unit(self, frame: Frame) -> None:
        run = _Run(frame, frame.pc, frame.units[frame.pc], self.kernel.now)
        self._current = run
        observer = self.line_observer
        if observer is not None:
            observer(frame.bank, run.unit.first, run.unit.last)
        self.runner.run(self._unit(run))

    def _unit_done(self, flow: object) -> None:
        run = self._current
        if run is None or flow is CANCELLED:
            return
        self._current = None
        frame = run.frame
        frame.last, frame.pc = run.index, run.index + 1
        if isinstance(flow, (ast.Call, ast.Loop, ast.LoopEnd, ast.StartBank)):
            self._flow(flow, frame, run.index)
        if self._terminate_pending:
            self.terminate()
        elif self._stop_pending or self.state == STEPPING:
            self._stop_pending = False
            self.state = PAUSED
        elif self.state == RUNNING:
            at = max(self.kernel.now, run.start + max(run.steps, 1) * STEP_NS)
            self._timer = self.kernel.schedule_at(at, self._next, priority=PRIO_LOGIC,
                                                  name="bank-line")

    def _flow(self, flow: object, frame: Frame, index: int) -> None:
        """``C`` ``J`` ``[#`` ``X`` ``X-`` at the end of their line (2.2.2)."""
        if isinstance(flow, ast.Loop):
            if len(frame.loops) < MAX_LOOP_DEPTH:
                frame.loops.append([index + 1, flow.count or -1])
        elif isinstance(flow, ast.LoopEnd):
            self._loop_back(frame, index + 1)
        elif isinstance(flow, ast.StartBank):
            self._call(ast.Call("J", flow.index or 0))
        elif isinstance(flow, ast.Call):
            self._call(flow)

    def _call(self, call: ast.Call) -> None:
        bank = self.motor.banks.get(False, call.index)
        if bank is None:
            self.motor.report_error(self.ctx, NoProgramBankError())
            return
        if call.kind == "J":
            self.stack = [Frame(call.index, program_units(bank))]
            return
        if len(self.stack) >= MAX_CALL_DEPTH or any(f.bank == call.index for f in self.stack):
            return  # 2.2.2 "cannot be called again", "under 10": the call is not made
        self.stack.append(Frame(call.index, program_units(bank)))

    # -- one line -------------------------------------------------------------------
    def _unit(self, run: _Run) -> LineGen:
        for stmt in run.unit.statements:
            flow = yield from self._statement(stmt, run)
            if run.cancelled:
                return CANCELLED
            if flow is not None:
                return flow
            if self.state not in (RUNNING, STEPPING):
                yield HOLD
        if run.paths is not None:
            report_leftovers(run.paths.pairing, self.ctx)
        waiting = tuple(m.motor for m in run.motions.values() if m.wait)
        if waiting:
            yield MotionWait(waiting)
        return None

    def _statement(self, stmt: ast.Statement, run: _Run) -> Step:
        run.steps += statement_steps(stmt) if not isinstance(stmt, ast.Branch) else 0
        if isinstance(stmt, ast.Ref):
            yield from self._ref(stmt, run)
        elif isinstance(stmt, ast.Move):
            yield from self._motion(stmt.kind, stmt.index or 0, stmt.motor, stmt.modifier, run)
        elif isinstance(stmt, ast.Branch):
            return (yield from self._branch(stmt, run))
        elif isinstance(stmt, (ast.Call, ast.Loop, ast.LoopEnd)):
            return stmt
        elif isinstance(stmt, ast.StartBank) and stmt.kind == "B":
            return stmt if stmt.index is not None else None
        elif isinstance(stmt, ast.Interp):
            yield from self._interp(stmt, run)
        elif isinstance(stmt, ast.Wait):
            return None  # W only inside a branch
        else:
            self._plain(stmt, run)
        return None

    def _plain(self, stmt: ast.Statement, run: _Run) -> None:
        run_plain(self.motor, stmt, self.ctx)
        if isinstance(stmt, ast.Exec) and stmt.op in _MOTION_EXECS:
            target = target_motor(self.motor, stmt)
            if target is not None and not target.motion_done():
                run.motions.setdefault(target.id, _Motion(target))

    def _branch(self, branch: ast.Branch, run: _Run) -> Step:
        run.steps += expr_steps(branch.condition)
        truth = holds(self.motor, branch.condition)
        actions = branch.then if truth else branch.orelse
        if truth and branch.then and isinstance(branch.then[0], ast.Wait):
            timed_out = yield wait_branch(self.motor, branch, branch.then[0])
            actions = () if timed_out else branch.orelse
        for stmt in actions:
            flow = yield from self._statement(stmt, run)
            if flow is not None or run.cancelled:
                return flow
        return None

    def _ref(self, stmt: ast.Ref, run: _Run) -> Steps:
        reg = stmt.reg
        target = target_motor(self.motor, stmt)
        if target is None:
            return
        if reg.kind == "P":
            yield from self._motion("P", reg.number, reg.motor, stmt.modifier, run)
        elif reg.kind == "T":
            ns = timer_ns(self.motor, reg)
            if ns:
                yield Sleep(ns)
        elif reg.kind == "S":
            target.program.sel_s = reg.number
        elif reg.kind == "A":
            self._accel(target, reg.number, run)
        elif reg.kind in ("N", "R"):
            target.program.sel_path = target.program.sel_path.select(reg.kind, reg.number,
                                                                      stmt.modifier)
        elif reg.kind == "M":
            _guard(target, lambda: target.select_torque_limit(
                target.memory.number("M", reg.number)))
        elif reg.kind in ("V", "K", "H"):
            _guard(target, lambda: target.say(self.ctx, display_reply(target, reg)))

    def _accel(self, target: MotorCore, index: int, run: _Run) -> None:
        """First A of a line: acceleration; a second A: the deceleration (4.1.3)."""
        seen = run.accel_seen.get(target.id, 0)
        run.accel_seen[target.id] = seen + 1
        if seen == 0:
            target.program.sel_a = index
        else:
            run.decel[target.id] = index

    def _motion(self, kind: str, index: int, motor_id: int | None, modifier: str | None,
                run: _Run) -> Steps:
        """``P`` ``Y`` ``Q`` ``Z``: start (or extend, merge) the motion of one motor."""
        target = (self.motor if motor_id is None or motor_id == self.motor.id
                  else self.motor.bus.motor(motor_id))
        if target is None:
            return
        if target.id in self.unwaited and target.id not in run.motions:
            if not target.motion_done():
                yield MotionWait((target,))   # 4.3.2: a series of Y completes each motion
            self.unwaited.discard(target.id)
        if run.paths is not None and run.paths.busy(target):
            yield MotionWait((target,))       # a path of this line completes first (4.4)
        try:
            _add_motion(target, run, kind, index, modifier, self.kernel.now,
                        self._delay(run, target))
        except (MotorError, LookupError, ValueError):
            target.report_error(self.ctx, OutOfRangeError())
            return
        if kind in ("Y", "Z"):
            self.unwaited.add(target.id)

    def _interp(self, stmt: ast.Interp, run: _Run) -> Steps:
        """``@#.n`` (2.1.2, 4.4, :mod:`.coordinated`): pairs with the ``@`` of an adjacent
        ID on the line; the pair's running motions complete first, unless it continues
        a path of this line (merged legs, RT3 1.1 ";")."""
        target = target_motor(self.motor, stmt)
        if target is None:
            return
        paths = run.paths = run.paths or LinePaths(self.kernel.now)
        try:
            limits = _limits(target, run)
        except ValueError:
            limits = None                    # S or A is 0: no path (error00 if X)
        try:
            pair = paths.pairing.add(request(target, stmt, target.program.sel_path, limits,
                                             self._delay(run, target)))
        except (MotorError, LookupError):
            target.report_error(self.ctx, OutOfRangeError())
            return
        if pair is not None:
            busy = paths.busy_before(*pair, self.kernel.now)
            if busy:
                yield MotionWait(busy)
            self.unwaited.difference_update(r.motor.id for r in pair)
            path = paths.start_or_report(*pair, self.kernel.now, self.ctx)
            for r in pair if path is not None else ():
                if getattr(run.motions.get(r.motor.id), "path", None) is not path:
                    run.motions[r.motor.id] = _Motion(r.motor, issued_at=self.kernel.now,
                                                      path=path)

    def _delay(self, run: _Run, target: MotorCore) -> int:
        """ns until this line's statements for ``target`` reach it down (or up) the chain
        as one message (ch. 3 K65; 0 without pacing)."""
        if target is self.motor:
            return 0
        if target.id not in run.arrivals:
            size = message_bytes(run.unit.statements, target.id, self.motor.id)
            run.arrivals[target.id] = self.motor.bus.relay(self.motor.id, target.id, size)
        return max(run.arrivals[target.id] - self.kernel.now, 0)


def _bank_context(motor: MotorCore) -> Context:
    from ..context import Context
    return Context(origin="bank", default_motor=motor.id, program=True)


def _guard(motor: MotorCore, action: object) -> None:
    try:
        action()  # type: ignore[operator]
    except (MotorError, LookupError, ValueError):
        motor.report_error(None, OutOfRangeError())


def _has_flow(unit: Unit) -> bool:
    return any(isinstance(s, (ast.Call, ast.Loop, ast.LoopEnd, ast.StartBank))
               for s in unit.statements)


def _limits(target: MotorCore, run: _Run) -> Limits | None:
    prog = target.program
    s_value = target.memory.number("S", prog.sel_s)
    a_value = target.memory.number("A", prog.sel_a)
    decel = run.decel.get(target.id)
    decel_a = None if decel is None else target.memory.number("A", decel)
    return target.limits(s_value, a_value, decel_a)


def _add_motion(target: MotorCore, run: _Run, kind: str, index: int, modifier: str | None,
                now: int, delay: int = 0) -> None:
    if modifier is not None and not target.resolution.incremental_allowed:
        raise OutOfRangeError()   # ch. 3 K37: "40-70, the incremental motion cannot be executed"
    value = target.memory.number("P", index)
    motion = run.motions.get(target.id)
    if motion is None or motion.issued_at != now:
        motion = run.motions[target.id] = _Motion(target, issued_at=now, delay=delay)
    limits = _limits(target, run)
    motion.push, motion.wait = kind in ("Q", "Z"), kind in ("P", "Q")
    if value == units_mod.CONTINUOUS and modifier is None:
        s_value = target.memory.number("S", target.program.sel_s)
        motion.waypoints, motion.continuous = [], (s_value, limits)
        target.run_continuous(s_value, limits)
        return
    if modifier is not None:
        base = motion.waypoints[-1][0] if motion.waypoints else _base(target)
        value = round(base + (value if modifier == "+" else -value))
    motion.waypoints.append((float(value), limits))
    motion.continuous = None
    _issue(motion, motion.waypoints)


def _base(target: MotorCore) -> float:
    """Where a relative ``P#+`` starts: the motor's target, or where it is (2.2.2 "P")."""
    aim = target.axis.target()
    return aim if abs(aim) != float("inf") else float(target.position())


def _issue(motion: _Motion, waypoints: list[tuple[float, Limits | None]]) -> None:
    if motion.push:
        *via, (aim, limits) = waypoints
        motion.motor.push_to(aim, limits, via=via)
    else:
        motion.motor.move_to(list(waypoints), delay_ns=motion.delay)
    motion.profile = motion.motor.axis.profile
    motion.waypoints = list(waypoints)


def _unfinished(motion: _Motion, now: int) -> list[tuple[float, Limits | None]] | None:
    """Waypoints a pause (or an alarm) left unreached: those not yet passed (4.1.2)."""
    motor = motion.motor
    if motion.continuous is not None or not motion.waypoints:
        return None
    final = motion.waypoints[-1][0]
    if motor.motion_done() and abs(motor.position() - final) <= motor.k(55):
        return None
    times = motion.profile.passing_times_ns() if motion.profile is not None else []
    passed = sum(1 for t, _ in times if t <= now)
    return motion.waypoints[passed:] or None
