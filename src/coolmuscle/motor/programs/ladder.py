"""Ladder logic banks and logic motion banks of one motor (cml-users-guide.txt 2.2.3, 4.5,
ch. 3 K62/K63; cm-banks-rt3.txt §3).

A running ladder bank is *scanned*: every scan runs the bank from its first line to
``END`` and starts again on the next cycle of K63 ms (K87 under the RT3 profile;
K63 = 0: no scans).  Each step takes 250 µs (RT3 3.4, steps counted by
:func:`.bankcheck.statement_steps` for what is actually executed), so a scan of N
steps occupies N x 0.25 ms; when that is longer than the cycle, the rest carries over
and the next scan starts when this one ends (ch. 3 K63; RT3 3.5.2 "scanned as fast as
possible"): scans start every max(K63, N x 0.25 ms).  A scan runs its statements at
the instant it starts (one kernel event); ``T#`` and ``W#`` suspend it in virtual time.

In a ladder bank an assignment displays its result unless its line ends with ``;``
(RT3 1.1), a register named alone displays its value (4.5.1 "P1.1 ... Display P1
value"), ``T#`` waits, ``CL#`` calls (10 levels, no recursion), ``JL#`` makes another
bank the scanned one (RT3 3.2).  ``[L#`` starts, ``]L`` pauses (twice: stops), ``[L``
resumes; K62 (RT3: K85) starts a bank at power-up.  A logic motion bank (``[LM#``,
RT3 3.6) is scanned every 1 ms whatever K63 says; it moves the motor by writing a V
bound to "Dx" (target position) or "St" (target speed).
"""

from __future__ import annotations

from collections.abc import Generator
from typing import TYPE_CHECKING

from ...cml import ast
from ...errors import MotorError, NoLadderBankError, OutOfRangeError
from ...sim.kernel import NS_PER_MS, PRIO_LOGIC, Timer
from ...sim.memo import Key, Memo
from ..state.memory import VState
from .bankcheck import expr_steps, statement_steps
from .bankexec import (
    HOLD,
    STEP_NS,
    LineGen,
    LineObserver,
    Request,
    Runner,
    Sleep,
    Unit,
    Watch,
    holds,
    ladder_units,
    run_plain,
    target_motor,
    timer_ns,
    wait_branch,
)
from .compiled import Compiled, compile_statement
from .direct import assign_value
from .queries import display_reply, format_value, register_name

if TYPE_CHECKING:
    from ..context import Context
    from ..core import MotorCore

IDLE, RUNNING, PAUSED = "idle", "running", "paused"
MAX_CALL_DEPTH = 10   # 2.2.3 "CL": "The maximum layer (nesting) should be under 10"
LOGIC_MOTION_PERIOD_NS = NS_PER_MS   # RT3 3.6 "These banks execute on 1 ms intervals"
_JUMP = object()
_GONE = object()
_PAUSED = object()
Step = Generator[Request, object, object]
_Code = tuple[ast.Statement, "Compiled | None", bool]
#: Banks whose compiled statements a runner keeps (more than a motor has).
CODES = 64


class LadderRunner:
    """Scans one ladder bank: the ladder (``motion=False``) or the logic motion bank."""

    def __init__(self, motor: MotorCore, *, motion: bool = False) -> None:
        from ..context import Context
        self.motor = motor
        self.kernel = motor.kernel
        self.motion = motion
        self.state = IDLE
        self.bank: int | None = None
        self.runner = Runner(motor, self._scan_done)
        self.ctx = Context(origin="ladder", default_motor=motor.id, ladder=True)
        self.scans = 0                 # completed scans (benchmarks, tests)
        self.scan_start = 0
        self.clock = 0                 # where the scan's steps have got to (ns)
        self._last_scan = -STEP_NS       # start of the last scan (a restart waits a step)
        self._timer: Timer | None = None
        self._scan_id = 0
        self._running_id = 0
        #: The compiled statements of each bank, by (number, version of the banks).
        self._codes: Memo[Key, tuple[_Code, ...]] = Memo(CODES)
        self._line_observer: LineObserver | None = None
        self._period = self.period_ns()
        if not motion:
            motor.params.on_change(self._param_changed)

    # -- control ----------------------------------------------------------------
    def period_ns(self) -> int | None:
        """The scan cycle: 1 ms for logic motion, else K63/K87 ms; None = not scanned."""
        if self.motion:
            return LOGIC_MOTION_PERIOD_NS
        period = self.motor.k(self.motor.firmware.ladder_period_k)
        return period * NS_PER_MS if period > 0 else None

    def _refresh_period(self) -> None:
        self._period = self.period_ns()

    def start(self, number: int, ctx: Context | None = None) -> None:
        """``[L#`` / ``[LM#``: scan bank ``number`` from now (error06 if it does not exist)."""
        if self.motor.banks.get(True, number) is None:
            self.motor.report_error(ctx, NoLadderBankError())
            return
        if not self.motion and self.motor.inputs.ladder_held():
            return  # K27/K30 function 5 "Stop Ladder Logic Bank" is on
        self.stop()
        self.bank, self.state = number, RUNNING
        self.scan_start = self.clock = self.kernel.now
        self._refresh_period()
        self._schedule(None if self._period is None else self.kernel.now)

    def pause(self) -> None:
        """``]L``: pause; a second ``]L`` stops (6.5 "]L")."""
        if self.state == PAUSED:
            self.stop()
        elif self.state == RUNNING:
            self.state = PAUSED
            self._cancel()
            self.runner.halt()

    def resume(self) -> None:
        """``[L``: continue the paused bank (6.5 "Only [L restarts ...")."""
        if self.state != PAUSED:
            return
        self.state = RUNNING
        self._refresh_period()
        if self.runner.busy:
            self.runner.rearm()
        else:
            self._schedule(self._due())

    def stop(self) -> None:
        """Stop scanning for good (``]L`` twice, input function 5, ``L100``)."""
        self._cancel()
        self._scan_id += 1
        self.runner.abandon()
        self.state = IDLE
        self.bank = None

    def power_up(self) -> None:
        """K62 (RT3: K85): the ladder bank started when the motor is powered on."""
        number = self.motor.k(self.motor.firmware.ladder_bank_k)
        if number > 0 and self.motor.banks.get(True, number) is not None:
            self.start(number)

    @property
    def line_observer(self) -> LineObserver | None:
        """Told of every line a scan reaches (bank coverage); ``None``: nobody asks.

        Setting it recompiles the banks: observed, each line's statements are preceded
        by one that reports the line (:func:`_reporting`); unobserved, the compiled
        statements are as they were, so the scans cost nothing more."""
        return self._line_observer

    @line_observer.setter
    def line_observer(self, observer: LineObserver | None) -> None:
        self._line_observer = observer
        self._codes.clear()

    # -- scheduling -----------------------------------------------------------------
    def _cancel(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _due(self) -> int | None:
        """When the next scan may start: max(start + cycle, end of this scan)."""
        period = self._period
        if period is None:
            return None
        return max(self.scan_start + period, self._scan_end(), self.kernel.now)

    def _scan_end(self) -> int:
        """When this scan's steps are done: 250 µs a step for a ladder bank (RT3 3.4);
        a logic motion bank is on its 1 ms grid whatever its steps (RT3 3.6: the 6-step
        example's "timing is less than 1ms"; docs/fidelity.md)."""
        return self.scan_start if self.motion else self.clock

    def _schedule(self, at: int | None) -> None:
        self._cancel()
        if at is None or self.state != RUNNING:
            return
        # a scan lasts at least its first step (RT3 3.4), even when a bank restarts
        # itself ([L# inside the bank): virtual time always moves between scans
        at = max(at, self._last_scan + STEP_NS)
        self._timer = self.kernel.schedule_at(at, self._scan, priority=PRIO_LOGIC,
                                              name="ladder-scan")

    def _param_changed(self, k: int, old: int, new: int) -> None:
        del old, new
        if k != self.motor.firmware.ladder_period_k:
            return
        self._refresh_period()
        if self.state == RUNNING and not self.runner.busy:
            self._schedule(self._due())

    def _scan(self) -> None:
        self._timer = None
        if self.state != RUNNING or self.bank is None:
            return
        self.scan_start = self.clock = self._last_scan = self.kernel.now
        self._running_id = self._scan_id
        start = self._fast_scan(self.bank)
        if start is None:
            # _scan_done(None) written out for the common case (a scan ran through)
            self.scans += 1
            self.motor.bus.poke()
            period = self._period
            if self.state == RUNNING and period is not None and self._timer is None:
                now = self.kernel.now
                at = max(self.scan_start + period, self._scan_end(), now,
                         self._last_scan + STEP_NS)
                self._timer = self.kernel.schedule_at(at, self._scan, priority=PRIO_LOGIC,
                                                      name="ladder-scan")
            elif self.state == RUNNING:
                self._schedule(self._due())
        elif start is not _GONE:
            self.runner.run(self._scan_gen(*start))  # type: ignore[misc]

    def _scan_done(self, result: object) -> None:
        if result is _GONE:
            return
        self.scans += 1
        self.motor.bus.poke()
        if self.state == RUNNING:
            self._schedule(self._due())

    # -- one scan ---------------------------------------------------------------------
    def _fast_scan(self, number: int) -> tuple[int, object] | object | None:
        """Run the compiled statements of the scanned bank in a plain loop.

        Returns ``None`` when the scan is complete, else where the interpreter must
        take over: (index of the statement, what it left to do or ``None``).
        """
        code = self._code(number)
        if code is None:
            return (0, None)
        self.clock += STEP_NS   # RT3 3.4: the start of the bank is a step
        scan_id = self._scan_id
        for index, (_, fn, _) in enumerate(code):
            if fn is None:
                return (index, None)
            flow = fn()
            if scan_id != self._scan_id:
                return _GONE
            if flow is not None or self.state == PAUSED:
                return (index, flow if flow is not None else _PAUSED)
        return None

    def _scan_gen(self, index: int, flow: object) -> LineGen:
        assert self.bank is not None
        result = yield from self._bank(self.bank, (), index, flow)
        return _GONE if self._running_id != self._scan_id else result

    def _code(self, number: int) -> tuple[_Code, ...] | None:
        """The compiled statements of a bank (compiled once per version of the banks)."""
        key: Key = (number, self.motor.banks.version)
        code = self._codes.get(key)
        if code is None:
            bank = self.motor.banks.get(True, number)
            if bank is None:
                return None
            observer = self._line_observer
            code = self._codes.put(key, tuple([
                entry for unit in ladder_units(bank, self.motor.firmware.ladder_displays)
                for entry in ([] if observer is None or not unit.statements
                               else [_reporting(observer, number, unit)])
                + [(stmt, compile_statement(stmt, self.motor, self.ctx, unit.quiet, self,
                                            _assigned), unit.quiet)
                   for stmt in unit.statements]]))
        return code

    def _bank(self, number: int, callers: tuple[int, ...], start: int = -1,
              pending: object = None) -> Step:
        """Interpret bank ``number``; ``start`` >= 0 continues a scan the fast loop began
        (``pending``: what its statement left to do)."""
        flow: object
        code = self._code(number)
        if code is None:
            self.motor.report_error(self.ctx, NoLadderBankError())
            return None
        callers += (number,)
        if start < 0:
            self.clock += STEP_NS   # RT3 3.4: the start of the bank is a step
            start = 0
        elif pending is not None:
            flow = HOLD if pending is _PAUSED else None
            if flow is HOLD:
                yield HOLD
            else:
                flow = yield from self._tail(pending, callers)
            if flow is _JUMP or self._running_id != self._scan_id:
                return flow if flow is _JUMP else _GONE
            start += 1
        for stmt, fn, quiet in code[start:]:
            if fn is None:
                flow = yield from self._statement(stmt, quiet, callers)
            else:
                flow = fn()
                if flow is not None:
                    flow = yield from self._tail(flow, callers)
            if self._running_id != self._scan_id:
                return _GONE
            if flow is _JUMP:
                return _JUMP
            if self.state == PAUSED:
                yield HOLD
        return None

    def _tail(self, flow: object, callers: tuple[int, ...]) -> Step:
        """What a compiled statement left to do: wait (``T#``) or call (``CL``, ``JL``)."""
        if isinstance(flow, Sleep):
            yield from self._sleep(flow.ns)
            return None
        if isinstance(flow, ast.Call):
            return (yield from self._call(flow, callers))
        return None

    def _sleep(self, ns: int) -> Step:
        wake = max(self.clock, self.kernel.now) + ns
        yield Sleep(wake - self.kernel.now)
        self.clock = wake
        return None

    def _statement(self, stmt: ast.Statement, quiet: bool, callers: tuple[int, ...]) -> Step:
        if isinstance(stmt, ast.Branch):
            return (yield from self._branch(stmt, quiet, callers))
        self.clock += statement_steps(stmt) * STEP_NS
        if isinstance(stmt, ast.Assign):
            self._assign(stmt, quiet)
        elif isinstance(stmt, ast.Ref):
            yield from self._ref(stmt)
        elif isinstance(stmt, ast.Call):
            return (yield from self._call(stmt, callers))
        elif isinstance(stmt, (ast.StartBank, ast.StopBank)) and stmt.kind in ("L", "LM"):
            self._bank_command(stmt)
        elif not isinstance(stmt, ast.Wait):
            run_plain(self.motor, stmt, self.ctx)
        return None

    def _branch(self, branch: ast.Branch, quiet: bool, callers: tuple[int, ...]) -> Step:
        self.clock += expr_steps(branch.condition) * STEP_NS
        truth = holds(self.motor, branch.condition)
        actions = branch.then if truth else branch.orelse
        if truth and branch.then and isinstance(branch.then[0], ast.Wait):
            watch = wait_branch(self.motor, branch, branch.then[0])
            if watch.timeout_ns is not None:   # the timer runs from the scan's step clock
                ahead = max(self.clock - self.kernel.now, 0)
                watch = Watch(watch.holds, watch.timeout_ns + ahead)
            timed_out = yield watch
            self.clock = max(self.clock, self.kernel.now)
            actions = () if timed_out else branch.orelse
        for stmt in actions:
            flow = yield from self._statement(stmt, quiet, callers)
            if flow is not None:
                return flow
        return None

    def _ref(self, stmt: ast.Ref) -> Step:
        reg = stmt.reg
        if reg.kind == "T":
            ns = timer_ns(self.motor, reg)
            if ns:
                yield from self._sleep(ns)
            return None
        target = target_motor(self.motor, stmt)
        if target is not None:
            try:
                target.say(self.ctx, display_reply(target, reg))
            except (MotorError, LookupError):
                target.report_error(self.ctx, OutOfRangeError())
        return None

    def _assign(self, stmt: ast.Assign, quiet: bool) -> None:
        """Store, and display ``V1.1=123`` unless the line ends with ``;`` (RT3 1.1)."""
        target = target_motor(self.motor, stmt)
        if target is None:
            return
        try:
            value = assign_value(target, stmt, self.ctx)
            if not quiet:
                target.say(self.ctx, _assigned(target, stmt.target, value))
        except MotorError as error:
            target.report_error(self.ctx, error)
        except (LookupError, ValueError):
            target.report_error(self.ctx, OutOfRangeError())

    def _call(self, call: ast.Call, callers: tuple[int, ...]) -> Step:
        """``CL#`` / ``JL#``; ``C#`` / ``J#``, which only RT3 loads into a logic bank
        (its 1.1 examples), are the same (docs/fidelity.md "CL / JL")."""
        if call.kind in ("J", "JL"):
            if self.motor.banks.get(True, call.index) is None:
                self.motor.report_error(self.ctx, NoLadderBankError())
                return None
            self.bank = call.index   # RT3 3.2 "JL": it will not return
            return _JUMP
        if len(callers) >= MAX_CALL_DEPTH or call.index in callers:
            return None  # 6.4 "impossible to ... re-call itself": the call is not made
        return (yield from self._bank(call.index, callers))

    def _bank_command(self, stmt: ast.StartBank | ast.StopBank) -> None:
        runner = self.motor.logic_motion if stmt.kind == "LM" else self.motor.ladder
        if isinstance(stmt, ast.StopBank):
            runner.pause()
        elif stmt.index is None:
            runner.resume()
        else:
            runner.start(stmt.index, self.ctx)


def _reporting(observer: LineObserver, bank: int, unit: Unit) -> _Code:
    """A statement that only tells ``observer`` the line is reached: it takes no step
    and returns no flow, so the scan goes on exactly as without it."""
    first, last = unit.first, unit.last

    def report() -> None:
        observer(bank, first, last)
    return unit.statements[0], report, unit.quiet


def _assigned(target: MotorCore, reg: ast.Reg, value: int | str | None) -> str:
    """The display of an assignment: the register as written, ``=`` and what it holds."""
    name = register_name(reg.kind, reg.index, target.id)
    if reg.kind == "K":
        return f"{name}={target.k(reg.number)}"
    stored = target.memory.get(reg.kind, reg.number)
    if isinstance(stored, VState) and isinstance(value, int):
        return f"{name}={value}"
    return f"{name}={format_value(stored)}"
