"""Kernel benchmark: simulated seconds per wall second.

Run: ``PYTHONPATH=src python bench/bench_kernel.py`` (about 15-30 s).

One CM2 motor loops a point-to-point program with event reporting (K23=1): S=100,
A=100, alternately to 20000 and 0 (2.1 s a move).  Program banks are not on main
yet, so the host drives the loop through the device API: when ``Ux.1=8`` arrives it
writes the next P0 (``set_register``) and executes ``^.1`` on the next whole
millisecond (a host that scans every millisecond, like a PLC).

* **closed form**: the real model (:class:`~coolmuscle.chain.daisy.Chain`) in fast virtual
  time; the kernel jumps from event to event (a move is a handful of events).
* **naive 1 ms tick**: the same moves simulated by a fixed-step loop that, every
  millisecond, evaluates everything the motor shows (command, position, error, speed,
  acceleration, torque, in-position test, status, output word, analog output) and
  runs the same host logic.  It uses the same planner and servo solution, so its
  samples are the same numbers: the benchmark asserts that both traces are identical
  at every millisecond of a common window, then times each alone.  Its in-position
  test is the model's rule (ch. 3 K55): the actual position within K55 of the target
  once the command is on its final approach (from where it stays within K55 of the
  target, a few ms before it ends), tested at each tick; the model finds the instant
  itself and the host answers on the next whole millisecond, so both start the next
  move on the same tick.  That move then reverses while the command still
  decelerates, and the loop plans and solves it as the axis does (``Axis.move``: the
  command runs on to its end, the new move starts there from rest).

A third run plays the loop as a real program bank (``B1.1`` / ``X0.1`` /
``S1.1, A1.1, P1.1`` / ``P2.1`` / ``X.1-`` / ``END``, started with ``[1.1``): closed
form only, since a bank starts its next line at the exact in-position instant, which
a 1 ms loop cannot reproduce.

Goals: closed form >= 10,000x real time; closed form >= 50x faster than the 1 ms loop.

A repeated move reuses its solved shaft motion (the solution depends only on the
drive and the move relative to where it starts: docs/performance.md); the benchmark
prints the reuse count and, for comparison, the rate with every move solved afresh.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Any

from coolmuscle.chain.daisy import Chain
from coolmuscle.device.api import Event
from coolmuscle.motor.motion.axis import Axis
from coolmuscle.motor.motion.planner import Waypoint, limits_from_data, plan_moves
from coolmuscle.motor.motion.profile import Profile, hold, stops_then_restarts
from coolmuscle.motor.signals.analog_output import output_volts
from coolmuscle.motor.status import status_line
from coolmuscle.sim.kernel import NS_PER_MS, NS_PER_S
from coolmuscle.tools.trace.recorder import record as record_trace

TARGETS = (20000, 0)
S_VALUE, A_VALUE = 100, 100
WINDOW_S = 30            # traces compared over this many simulated seconds
CLOSED_S = 20_000        # simulated seconds timed for the closed form
NAIVE_S = 120            # simulated seconds timed for the 1 ms loop
GOAL_REALTIME, GOAL_SPEEDUP = 10_000, 50


def next_ms(t: int) -> int:
    """The first whole millisecond at or after ``t``."""
    return -(-t // NS_PER_MS) * NS_PER_MS


# -- closed form: the real model ----------------------------------------------------------
class ClosedForm:
    """The chain, plus the host that answers each in-position report with a new move."""

    def __init__(self, record: bool) -> None:
        self.chain = Chain()
        self.recorder = record_trace(self.chain) if record else None
        self.moves = 0
        self.reports: list[tuple[int, str]] = []
        self.chain.execute(f"S.1={S_VALUE}, A.1={A_VALUE}")
        self.chain.subscribe(self._event)
        self._go()

    def _event(self, event: Event) -> None:
        if event.kind == "status" and event.value == 8:
            self.reports.append((event.time, event.text))
            kernel = self.chain.kernel
            kernel.schedule_at(next_ms(kernel.now), self._go, name="host")

    def _go(self) -> None:
        self.chain.set_register(1, "P", 0, TARGETS[self.moves % 2])
        self.chain.execute("^.1")
        self.moves += 1

    def run(self, seconds: float) -> None:
        self.chain.kernel.run(until=round(seconds * NS_PER_S))


class Afresh(ClosedForm):
    """The closed form with every move planned and solved afresh: the chain's memos
    (``Chain.motion_memos``, coolmuscle.motor.motion.dynamics.MotionMemos) are emptied
    before each move, as if no two moves of the machine were alike."""

    def _go(self) -> None:
        self.chain.motion_memos.clear()
        super()._go()


class BankLoop:
    """The same loop as a program bank with an endless X0 loop (2.2.2 "X")."""

    PROGRAM = ("S1.1=100", "A1.1=100", "P1.1=20000", "P2.1=0", "B1.1", "X0.1",
               "S1.1, A1.1, P1.1", "P2.1", "X.1-", "END")

    def __init__(self, record: bool) -> None:
        del record
        self.chain = Chain()
        self.moves = 0
        self.chain.subscribe(self._event)
        for line in self.PROGRAM:
            self.chain.host_line.feed(line.encode() + b"\r")
        self.chain.execute("[1.1")

    def _event(self, event: Event) -> None:
        if event.kind == "status" and event.value == 8:
            self.moves += 1

    def run(self, seconds: float) -> None:
        self.chain.kernel.run(until=round(seconds * NS_PER_S))


# -- naive: a fixed 1 ms tick loop over the same moves -----------------------------------------
def solve(axis: Axis, profile: Profile, now: int, previous: Any) -> Any:
    """The load model's shaft solution for ``profile`` from ``now``, built as the axis
    builds it (coolmuscle.motor.motion.dynamics.Motion)."""
    from coolmuscle.motor.motion.dynamics import Motion
    p, v = (previous.position_at(now), previous.velocity_at(now)) if previous else (0, 0)
    return Motion(profile, now, p, v, axis._current_drive())


def shaft(solution: Any, profile: Profile, t: int) -> tuple[float, float, float]:
    """(command, actual position, actual speed), raw pulses."""
    return solution.command_at(t), solution.position_at(t), solution.velocity_at(t)


def torque(motor: Any, solution: Any, profile: Profile, t: int, speed: float) -> float:
    """Ix from the shaft motion, as the trace computes it."""
    return solution.torque_percent_at(t)


@dataclass
class Tick:
    """What the naive loop evaluates each millisecond."""

    command: float
    position: float
    speed: float
    torque: float
    status: int
    outputs: int
    analog_out: float


class Naive:
    """Fixed-step simulation: every millisecond evaluate the motor and run the host.

    A motor object of its own (never run by a kernel) only lends the model's
    parameters: its plant, servo gain and drive."""

    def __init__(self, record: bool) -> None:
        self.motor = Chain().motors[1]
        self.window = 5.0                 # K55
        self.ppr = 1000                   # K37=3
        self.limits = limits_from_data(S_VALUE, A_VALUE, k37=3, k44=100, k51=0, k69=0)
        self.profile = hold(0.0, 0)
        self.rest: Profile | None = None  # the plan from rest of a restarted reversal
        self.tracking = solve(self.motor.axis, self.profile, 0, None)
        self.shaft = shaft
        self.torque = torque
        self.target = 0.0
        self.approach: int | None = None  # the command's final approach (K55)
        self.moving = False
        self.moves = 0
        self.reports: list[tuple[int, str]] = []
        self.samples: list[Tick] | None = [] if record else None
        self.now = 0
        self._go()

    def _go(self) -> None:
        from coolmuscle.motor.motion.dynamics import Motion
        target, now = float(TARGETS[self.moves % 2]), self.now
        waypoints = [Waypoint(target, self.limits)]
        rest = self.rest
        command = rest if rest is not None and now >= rest.origin_ns else self.profile
        profile = plan_moves(command.state_at(now), waypoints, now)
        end = command.end_ns
        if end is not None and stops_then_restarts(self.profile, profile):
            # in position before the command ended, and the new move reverses: as
            # Axis.move, the command runs on to its end and the move starts from rest
            self.rest = plan_moves(command.state_at(end), waypoints, end)
            self.tracking = Motion.continued(self.tracking, now, self.rest)
        else:
            self.rest = None
            self.tracking = solve(self.motor.axis, profile, now, self.tracking)
        self.profile = profile
        self.target = target
        self.approach = self.profile.settles_ns(target, self.window)
        self.moving = True
        self.moves += 1

    def tick(self) -> None:
        t = self.now
        command, position, speed = self.shaft(self.tracking, self.profile, t)
        approaching = self.approach is not None and t >= self.approach
        if self.moving and approaching and abs(self.target - position) <= self.window:
            self.moving = False
            self.reports.append((t, status_line(1, 8)))   # K23=1 report
            self._go()                                     # the host, this millisecond
            command, position, speed = self.shaft(self.tracking, self.profile, t)
        ix = self.torque(self.motor, self.tracking, self.profile, t, speed)
        status = 0 if self.moving else 8
        outputs = 0                                        # K34=0000: no output functions
        analog = output_volts(0, target=self.target, position=position,
                              error=command - position, speed_pps=speed, torque=ix,
                              pulses_per_rev=self.ppr)
        if self.samples is not None:
            self.samples.append(Tick(command, position, speed, ix, status, outputs, analog))
        self.now += NS_PER_MS

    def run(self, seconds: float) -> None:
        end = round(seconds * NS_PER_S)
        while self.now <= end:
            self.tick()


# -- the benchmark ---------------------------------------------------------------------------
def compare_traces() -> int:
    """Both runs over WINDOW_S: identical samples at every millisecond; returns the count."""
    closed, naive = ClosedForm(record=True), Naive(record=True)
    closed.run(WINDOW_S)
    naive.run(WINDOW_S)
    assert closed.recorder is not None and naive.samples is not None
    for i, tick in enumerate(naive.samples):
        s = closed.recorder.sample(1, i * NS_PER_MS)
        got = Tick(s.command, s.position, s.speed, s.torque, s.status, s.outputs, s.analog_out)
        if got != tick:
            raise AssertionError(f"traces differ at {i} ms: closed form {got}, naive {tick}")
    if closed.moves != naive.moves or \
            [next_ms(t) for t, _ in closed.reports] != [t for t, _ in naive.reports]:
        raise AssertionError("the runs made different moves or reports")
    return len(naive.samples)


def timed(make: type[ClosedForm] | type[Naive] | type[BankLoop], seconds: float,
          repeat: int = 3) -> tuple[float, ClosedForm | Naive | BankLoop]:
    """Best wall time of ``repeat`` fresh runs (the least disturbed one)."""
    best, runner = float("inf"), None
    for _ in range(repeat):
        runner = make(record=False)
        start = time.perf_counter()
        runner.run(seconds)
        best = min(best, time.perf_counter() - start)
    assert runner is not None
    return best, runner


def main() -> int:
    samples = compare_traces()
    print(f"traces identical at all {samples} millisecond samples of {WINDOW_S} s "
          "(command, position, speed, torque, status, outputs, analog out)")
    wall_closed, closed = timed(ClosedForm, CLOSED_S)
    assert isinstance(closed, ClosedForm)
    hits, solves = closed.chain.motion_memos.reuse()
    wall_naive, naive = timed(Naive, NAIVE_S)
    assert isinstance(closed, ClosedForm)
    events = closed.chain.kernel.events_run
    rt_closed = CLOSED_S / wall_closed
    rt_naive = NAIVE_S / wall_naive
    speedup = rt_closed / rt_naive
    print(f"closed form : {CLOSED_S:>6} s simulated in {wall_closed:6.3f} s wall, "
          f"{closed.moves} moves, {events / closed.moves:.1f} events a move "
          f"-> {rt_closed:,.0f}x real time")
    print(f"naive 1 ms  : {NAIVE_S:>6} s simulated in {wall_naive:6.3f} s wall, "
          f"{naive.moves} moves, 1000 ticks a second -> {rt_naive:,.0f}x real time")
    print(f"              (repeated moves reuse their solution: {hits} reused, "
          f"{solves} solved in one run, its own chain)")
    wall_fresh, _ = timed(Afresh, CLOSED_S / 4)
    rt_fresh = CLOSED_S / 4 / wall_fresh
    print(f"every move solved afresh: {CLOSED_S // 4:>6} s simulated in {wall_fresh:6.3f} s wall "
          f"-> {rt_fresh:,.0f}x real time (no goal: shows what the reuse is worth)")
    ok_rt, ok_speed = rt_closed >= GOAL_REALTIME, speedup >= GOAL_SPEEDUP
    wall_bank, bank = timed(BankLoop, CLOSED_S)
    assert isinstance(bank, BankLoop)
    rt_bank = CLOSED_S / wall_bank
    print(f"program bank: {CLOSED_S:>6} s simulated in {wall_bank:6.3f} s wall, "
          f"{bank.moves} moves, {bank.chain.kernel.events_run / max(bank.moves, 1):.1f} "
          f"events a move -> {rt_bank:,.0f}x real time")
    print(f"ratio closed form / real time : {rt_closed:,.0f}x "
          f"(goal >= {GOAL_REALTIME:,}x: {'met' if ok_rt else 'NOT met'})")
    print(f"ratio closed form / naive     : {speedup:,.0f}x "
          f"(goal >= {GOAL_SPEEDUP}x: {'met' if ok_speed else 'NOT met'})")
    print(f"ratio program bank / real time: {rt_bank:,.0f}x "
          f"(goal >= {GOAL_REALTIME:,}x: {'met' if rt_bank >= GOAL_REALTIME else 'NOT met'})")
    return 0 if ok_rt and ok_speed else 1


if __name__ == "__main__":
    sys.exit(main())
