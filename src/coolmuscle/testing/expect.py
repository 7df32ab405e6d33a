"""Assertions that read like the machine, over what a chain did in virtual time.

``cm_chain.expect(motor)`` (:class:`MotorExpect`) checks the trace of one motor: its
position inside a window by a time, in position by a time (Ux bit 8, 6.6 ?99), no alarm
during a stretch (the alarm bits of ch. 3 K56/K57), peaks of torque, speed and driver
temperature below a limit (?98, ?97, ?71), an output on (or off) between two times
(?50; K33 applied, as the port reads).  Times are virtual seconds since the chain was
built.  A failure raises :class:`MotionAssertionError`: what was expected, what the motor
did, the bank line that was running then (its file and line when it came from a file)
and the piece of the trace around that instant; with a plot folder the whole trace is
drawn there too (``pytest --cm-plots DIR``).

Values come from the trace recorder (:mod:`coolmuscle.tools.trace.recorder`): exact at
any instant (closed-form motion), sampled for peaks on a 1 ms grid plus every change.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from ..motor.status import ALARM_BITS, Ux
from ..sim.kernel import NS_PER_S, seconds

if TYPE_CHECKING:
    from ..chain.daisy import Chain
    from ..tools.trace.recorder import Sample, TraceRecorder

__all__ = ["MotionAssertionError", "MotorExpect", "Recorded"]

#: Rows of the trace piece a failure shows.
PIECE_ROWS = 9
#: Virtual time a piece reaches back before the instant it is about.
PIECE_SPAN_S = 0.5


class Recorded(Protocol):
    """What the assertions read of a chain under test (:class:`~.rig.ChainRig`)."""

    chain: Chain
    recorder: TraceRecorder
    start_ns: int

    @property
    def now(self) -> float: ...

    def seconds(self, t: int) -> float: ...

    def temperatures(self, motor: int) -> list[tuple[int, int]]: ...

    def running_line(self, at: int, motor: int) -> str | None: ...

    def line_at(self, at: int, motor: int) -> str | None: ...

    def failure_plot(self) -> Path | None: ...


class MotionAssertionError(AssertionError):
    """A motion assertion that failed; the message holds the trace piece."""


def _ux(status: int) -> str:
    names = [flag.name.lower() for flag in Ux if flag and status & flag and flag.name]
    return f"{status} ({', '.join(names)})" if names else str(status)


def _num(value: float) -> str:
    if not math.isfinite(value):
        return "inf" if value > 0 else "-inf"
    return str(int(value)) if float(value).is_integer() else f"{value:.1f}"


class MotorExpect:
    """The assertions on one motor of a :class:`Recorded`."""

    def __init__(self, rig: Recorded, motor: int) -> None:
        if motor not in rig.chain.motor_ids:
            raise ValueError(f"motor {motor} is not on the chain "
                             f"(IDs {list(rig.chain.motor_ids)})")
        self.rig = rig
        self.motor = motor

    # -- values -----------------------------------------------------------------------
    def sample(self, at: float) -> Sample:
        """The motor's values at ``at`` virtual seconds (at most now)."""
        return self.rig.recorder.sample(self.motor, self._ns(at))

    def _ns(self, at: float) -> int:
        now = self.rig.chain.kernel.now
        t = self.rig.start_ns + seconds(at)
        if t > now:
            raise ValueError(f"{at:g} s is after now ({self.rig.now:.3f} s): run the "
                             "chain that far first (cm_chain.run)")
        return max(t, self.rig.start_ns)

    def _window(self, during: tuple[float, float] | None) -> tuple[int, int]:
        if during is None:
            return self.rig.start_ns, self.rig.chain.kernel.now
        return self._ns(during[0]), self._ns(during[1])

    def _times(self, t0: int, t1: int) -> list[int]:
        recorder = self.rig.recorder
        grid = range(t0, t1 + 1, NS_PER_S // 1000)
        changes = [t for t in recorder.change_times(t1) if t0 <= t <= t1]
        return sorted({*grid, *changes, t1})

    # -- assertions ---------------------------------------------------------------------
    def position(self, target: float, *, within: float = 0, by: float) -> None:
        """At ``by`` seconds the position (pulses, ?96) is ``target`` ± ``within``."""
        __tracebackhide__ = True     # pytest shows the test's line, not this
        value = self.sample(by).position
        if abs(value - target) > within:
            self.fail(f"position at {by:g} s is {_num(value)} pulses, expected {_num(target)}"
                      f" ± {_num(within)}", self._ns(by))

    def in_position(self, *, by: float) -> None:
        """At ``by`` seconds the motor is in position (Ux bit 8, 6.6 ?99)."""
        __tracebackhide__ = True     # pytest shows the test's line, not this
        t = self._ns(by)
        status = self.sample(by).status
        if not status & Ux.IN_POSITION:
            later = next((s for s in self._times(t, self.rig.chain.kernel.now)
                          if self.rig.recorder.sample(self.motor, s).status & Ux.IN_POSITION),
                         None)
            when = (f"; in position at {self.rig.seconds(later):.3f} s" if later is not None
                    else "; not in position since")
            self.fail(f"not in position at {by:g} s: Ux={_ux(status)}{when}", t)

    def no_alarm(self, *, during: tuple[float, float] | None = None) -> None:
        """No alarm bit (ch. 3 K56, K57) in Ux during the stretch (the whole run by default)."""
        __tracebackhide__ = True     # pytest shows the test's line, not this
        t0, t1 = self._window(during)
        for t in self._times(t0, t1):
            status = self.rig.recorder.sample(self.motor, t).status
            if status & ALARM_BITS:
                self.fail(f"alarm at {self.rig.seconds(t):.3f} s: Ux={_ux(status)}", t)

    def _peak(self, what: str, unit: str, limit: float, during: tuple[float, float] | None,
              value: Callable[[int], float]) -> None:
        t0, t1 = self._window(during)
        worst, at = max(((abs(value(t)), t) for t in self._times(t0, t1)),
                        default=(0.0, t0))
        if worst >= limit:
            self.fail(f"peak {what} {_num(worst)} {unit} at {self.rig.seconds(at):.3f} s, "
                      f"expected below {_num(limit)} {unit}", at)

    def peak_torque_below(self, limit: float, *,
                          during: tuple[float, float] | None = None) -> None:
        """|torque| stays below ``limit`` % of rated (?98) during the stretch."""
        __tracebackhide__ = True     # pytest shows the test's line, not this
        self._peak("torque", "%", limit, during,
                   lambda t: self.rig.recorder.sample(self.motor, t).torque)

    def peak_speed_below(self, limit: float, *,
                         during: tuple[float, float] | None = None) -> None:
        """|speed| stays below ``limit`` pulses per second during the stretch."""
        __tracebackhide__ = True     # pytest shows the test's line, not this
        self._peak("speed", "pps", limit, during,
                   lambda t: self.rig.recorder.sample(self.motor, t).speed)

    def peak_temperature_below(self, limit: float, *,
                               during: tuple[float, float] | None = None) -> None:
        """The driver temperature (°C, ?71) stays below ``limit`` during the stretch
        (read after every kernel event of the run, at most every 10 ms)."""
        __tracebackhide__ = True     # pytest shows the test's line, not this
        t0, t1 = self._window(during)
        readings = [(c, t) for t, c in self.rig.temperatures(self.motor) if t0 <= t <= t1]
        worst, at = max(readings, default=(-math.inf, t0))
        if worst >= limit:
            self.fail(f"peak temperature {_num(worst)} °C at {self.rig.seconds(at):.3f} s, "
                      f"expected below {_num(limit)} °C", at)

    def output(self, number: int, *, on: bool = True, between: tuple[float, float]) -> None:
        """Output ``number`` (1..) is on (or off) the whole time from ``between[0]`` to
        ``between[1]`` seconds, as the port reads (?50, K33 applied)."""
        __tracebackhide__ = True     # pytest shows the test's line, not this
        bit = 1 << (number - 1)
        t0, t1 = self._window(between)
        for t in self._times(t0, t1):
            outputs = self.rig.recorder.sample(self.motor, t).outputs
            if bool(outputs & bit) != on:
                self.fail(f"output {number} is {'off' if on else 'on'} at "
                          f"{self.rig.seconds(t):.3f} s, expected {'on' if on else 'off'} "
                          f"from {between[0]:g} to {between[1]:g} s", t)

    # -- failing ----------------------------------------------------------------------
    def fail(self, what: str, at: int) -> None:
        """Raise :class:`MotionAssertionError` about ``at`` (kernel ns)."""
        __tracebackhide__ = True     # pytest shows the test's line, not this
        parts = [f"motor {self.motor}: {what}"]
        running = self.rig.running_line(at, self.motor)
        if running:
            parts.append(f"  bank line running then: {running}")
        parts.append(f"  trace of motor {self.motor} (virtual time):")
        parts += ["    " + row for row in self.piece(at)]
        plot = self.rig.failure_plot()
        if plot is not None:
            parts.append(f"  plot: {plot}")
        raise MotionAssertionError("\n".join(parts))

    def piece(self, at: int) -> list[str]:
        """The trace around ``at``: :data:`PIECE_ROWS` rows up to it and one after."""
        start = max(self.rig.start_ns, at - seconds(PIECE_SPAN_S))
        step = max((at - start) // (PIECE_ROWS - 1), 1)
        after = min(at + step, self.rig.chain.kernel.now)
        times = sorted({*range(start, at, step), at, after})
        return _table(self.rig, self.motor, times, at)


def _table(rig: Recorded, motor: int, times: Sequence[int], at: int) -> list[str]:
    header = ("time s", "target", "position", "speed pps", "torque %", "Ux", "outputs",
              "bank line")
    rows = [header]
    for t in times:
        s = rig.recorder.sample(motor, t)
        line = rig.line_at(t, motor) or ""
        rows.append((f"{rig.seconds(t):.3f}", _num(s.target), _num(s.position),
                     _num(s.speed), _num(s.torque), str(s.status), f"{s.outputs:b}", line))
    widths = [max(len(r[i]) for r in rows) for i in range(len(header) - 1)]
    out = []
    for instant, row in zip([None, *times], rows):
        mark = "->" if instant == at else "  "
        cells = [row[i].rjust(widths[i]) for i in range(len(widths))]
        out.append(f"{mark} {'  '.join(cells)}  {row[-1]}".rstrip())
    return out
