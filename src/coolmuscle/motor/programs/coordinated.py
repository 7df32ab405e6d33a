"""Interpolation execution: two adjacent motors follow one path (cml-users-guide.txt
2.1.2 "@", 2.2.2 "N" / "R", 4.4; cm-banks-rt3.txt 1.1 ";").

An ``@#.n`` names one motor of a pair and the P memory it ends at; the pair is the
``@`` of an adjacent ID on the same line (4.4 "adjacent Motor IDs").  The lower ID is
the X axis, the higher the Y axis (4.4.1 "Motor 1 (X axis)", "Motor 2 (Y axis)").  The
path starts at the motors' current commanded position and ends at their P data; its
shape comes from the R (radius, with the ``-`` modifier or a negative value for the
minor arc) or N (centre) data selected before the ``@`` (2.2.2 "N", "R"), or in direct
mode from R0 / N0, whichever was written last.  :mod:`.interp` draws it: the arc
length is planned like a one-axis move at the X motor's S and A, and each axis follows
its closed-form cubic pieces through :meth:`.axis.Axis.run_profile`, with the usual
tracking error, in-position report and trace.

Several pairs of one line, joined by ``;``, are legs of one merged path (4.4 "CM2 can
operate merge motion, during even at the interpolation"; RT3 1.1
``r2.1,r2.2,@1.2,@1.1; r1.1,r1.2,@2.2,@1.1``).  A stop (``]``, ``]1``) decelerates along
the path; ``[`` resumes the rest of it.  The choices the manual leaves open are listed
in docs/fidelity.md "Daisy chain".
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from ...cml import ast
from ...cml.formatter import format_statement
from ...errors import MotorError, OutOfRangeError
from ..motion.interp import (
    Leg,
    PathError,
    Point,
    SubPath,
    arc_from_center,
    arc_from_radius,
    follow_path,
    leg_starts,
    plan_path,
)
from ..motion.planner import Limits, plan_stop
from ..motion.profile import Profile

if TYPE_CHECKING:
    from ..context import Context
    from ..core import MotorCore

#: Arc length (pulses) below which the rest of a path counts as travelled.
_DONE = 1e-6


@dataclass(frozen=True, slots=True)
class Selection:
    """The R or N data the next ``@`` of a motor uses (2.2.2 "N", "R").

    ``kind`` is the register named last (``"R"`` radius or ``"N"`` centre); each kind
    keeps its own memory number.  ``modifier`` is the ``+`` / ``-`` written after ``R``
    (``-``: minor arc, ``+``: major arc; none: the sign of the R value decides).
    """

    kind: str = "R"
    r_index: int = 0
    n_index: int = 0
    modifier: str | None = None

    def select(self, kind: str, index: int, modifier: str | None) -> Selection:
        """The selection after ``R#`` / ``N#`` (with its modifier) is named."""
        if kind == "N":
            return replace(self, kind="N", n_index=index)
        return replace(self, kind="R", r_index=index, modifier=modifier)

    def index(self, kind: str) -> int:
        return self.n_index if kind == "N" else self.r_index


@dataclass(slots=True)
class Request:
    """One ``@#.n`` with what its motor contributes to the pair."""

    motor: MotorCore
    end_index: int            # P memory of the end point
    direction: str | None     # "+" CW, "-" CCW
    selection: Selection
    limits: Limits | None     # speed along the path when this motor is the X axis
    delay_ns: int = 0         # when the command reaches the motor (K65 chain timing)


def request(motor: MotorCore, stmt: ast.Interp, selection: Selection, limits: Limits | None,
            delay_ns: int = 0) -> Request:
    """A request for ``motor``; error00 (:class:`OutOfRangeError`) on a type without
    interpolation (2.1.2 "Only Interpolation type can be used") or a P memory that
    does not exist."""
    if not motor.firmware.has_interpolation:
        raise OutOfRangeError("@ needs the R (interpolation) type (2.1.2)")
    index = stmt.index or 0
    motor.memory.get("P", index)          # IndexError for a memory number not allocated
    return Request(motor, index, stmt.direction, selection, limits, delay_ns)


class Pairing:
    """The ``@`` of one line waiting for a partner (4.4 "adjacent Motor IDs").

    An ``@`` pairs with the earliest waiting ``@`` of the ID one above or one below;
    a second ``@`` of a motor whose first is still waiting replaces it.  Whatever is
    left unpaired at the end of the line is the caller's to report.
    """

    def __init__(self, at: int = 0) -> None:
        self.at = at
        self.waiting: list[Request] = []
        self.unpaired: list[Request] = []

    def add(self, req: Request) -> tuple[Request, Request] | None:
        """Add ``req``; the (X, Y) pair when it completes one."""
        for other in self.waiting:
            if other.motor.id == req.motor.id:
                self.waiting.remove(other)
                self.unpaired.append(other)
                break
        for other in self.waiting:
            if abs(other.motor.id - req.motor.id) == 1:
                self.waiting.remove(other)
                return (other, req) if other.motor.id < req.motor.id else (req, other)
        self.waiting.append(req)
        return None

    def leftovers(self) -> list[Request]:
        """Every ``@`` that found no partner (each is error00 of its motor)."""
        out = self.unpaired + self.waiting
        self.unpaired, self.waiting = [], []
        return out


def build_leg(x: Request, y: Request, start: Point) -> Leg:
    """The path from ``start`` to the pair's P data, shaped by the X motor's R / N
    selection (4.4.1-4.4.3), at the X motor's speed.  Raises :class:`PathError` when no
    path can be drawn and ``LookupError`` for memory numbers that do not exist."""
    xm, ym = x.motor, y.motor
    end = (float(xm.memory.get("P", x.end_index)), float(ym.memory.get("P", y.end_index)))
    if x.limits is None:
        raise PathError("the X motor has no speed or acceleration (S or A is 0)")
    kind = x.selection.kind
    cw = (x.direction or y.direction or "+") == "+"
    if kind == "N":
        center = (float(xm.memory.get("N", x.selection.n_index)),
                  float(ym.memory.get("N", y.selection.index("N"))))
        return Leg(arc_from_center(start, end, center, cw=cw), x.limits)
    rx = float(xm.memory.get("R", x.selection.r_index))
    ry = float(ym.memory.get("R", y.selection.index("R")))
    modifier = x.selection.modifier
    minor = modifier == "-" if modifier is not None else rx < 0
    return Leg(arc_from_radius(start, end, rx, ry, minor=minor, cw=cw), x.limits)


def _shifted(profile: Profile, delay_ns: int) -> Profile:
    if not delay_ns:
        return profile
    return Profile(profile.origin_ns + delay_ns, profile.segments,
                   start_state=profile.start_state, final_position=profile.final_position,
                   passing_times=profile.passing_times, checked=True)


class PairMotion:
    """The path a pair of motors follows: legs merged one after the other."""

    def __init__(self, x: MotorCore, y: MotorCore, delays: tuple[int, int] = (0, 0)) -> None:
        self.x, self.y = x, y
        self.delays = delays
        self.start: Point = (x.axis.command_position(), y.axis.command_position())
        self.legs: list[Leg] = []
        self.issued_at = -1
        self.s_profile: Profile | None = None
        self._raw: dict[int, Profile] = {}
        self._stopped_at: int | None = None

    @property
    def motors(self) -> tuple[MotorCore, MotorCore]:
        return self.x, self.y

    def end_point(self) -> Point:
        """Where the last leg ends."""
        if not self.legs:
            return self.start
        path = self.legs[-1].path
        return path.point(path.length)

    def owns(self, motor: MotorCore) -> bool:
        """Whether ``motor`` still follows this path (nothing else took it over)."""
        return motor.path is self and motor.axis.profile is self._raw.get(motor.id)

    def moving(self) -> bool:
        return any(self.owns(m) and m.axis.moving for m in self.motors)

    # -- planning -------------------------------------------------------------------
    def add(self, leg: Leg, now: int) -> None:
        """Append a leg at ``now`` (all legs of one line: the merge of 4.4) and run."""
        self.legs.append(leg)
        self.issued_at = now
        try:
            s_profile = plan_path(self.legs, 0.0, now)
        except PathError:           # nothing to travel: each motor just "arrives" (as ^)
            self.legs.pop()
            end = leg.path.point(leg.path.length)
            for motor, target in zip(self.motors, end):
                motor.move_to([(target, leg.limits)])
            return
        if not self._allowed():
            self.legs.pop()
            return
        self._follow(s_profile, self.motors)

    def _allowed(self) -> bool:
        """Both motors may go to the end (software limits, limit sensors): else neither
        moves (docs/fidelity.md "Daisy chain")."""
        end = self.end_point()
        return all([motor.path_end_allowed(target) for motor, target in zip(self.motors, end)])

    def _follow(self, s_profile: Profile, motors: Sequence[MotorCore]) -> None:
        self.s_profile = s_profile
        self._stopped_at = None
        x_profile, y_profile = follow_path(self.legs, s_profile)
        limits = self.legs[-1].limits
        for motor, profile, delay in ((self.x, x_profile, self.delays[0]),
                                      (self.y, y_profile, self.delays[1])):
            if motor in motors and motor.run_path(self, _shifted(profile, delay), limits):
                self._raw[motor.id] = motor.axis.profile

    # -- stop and resume (2.1.2 "]", "[") ---------------------------------------------
    def stop(self, now: int) -> None:
        """Decelerate along the path at the deceleration of the leg being travelled.

        Each motor stops on its own time line: with chain pacing the Y axis runs its
        part of the path a hop later than the X axis (``delays``)."""
        if self.s_profile is None or self._stopped_at == now or not self.moving():
            return
        self._stopped_at = now
        plans: dict[int, Profile] = {}
        for motor, delay in zip(self.motors, self.delays):
            if not self.owns(motor):
                continue
            t = now - delay
            state = self.s_profile.state_at(t)
            lim = self._leg_at(state[0]).limits
            plans[motor.id] = plan_stop(state, lim.decel, t, lim.scurve, creep=lim.creep,
                                        speed=lim.speed)
        if not plans:
            return
        if len(plans) == 2 and self.delays[0] == self.delays[1]:
            plans[self.y.id] = plans[self.x.id]          # one time line: one plan
        limits = self.legs[-1].limits
        followed: dict[int, tuple[Profile, Profile]] = {}
        for motor, delay in zip(self.motors, self.delays):
            plan = plans.get(motor.id)
            if plan is None:
                continue
            if id(plan) not in followed:
                followed[id(plan)] = follow_path(self.legs, plan)
            profile = followed[id(plan)][0 if motor is self.x else 1]
            if motor.run_path(self, _shifted(profile, delay), limits):
                self._raw[motor.id] = motor.axis.profile
        self.s_profile = plans.get(self.x.id) or plans[self.y.id]

    def _leg_at(self, s: float) -> Leg:
        starts, _ = leg_starts(self.legs)
        index = 0
        for i, s0 in enumerate(starts):
            if s >= s0:
                index = i
        return self.legs[index]

    def resume(self, now: int) -> None:
        """Travel the rest of the path from where a stop left it (``[`` after ``]``)."""
        if self.s_profile is None or not self.legs:
            return
        s_here = self.s_profile.final_position
        starts, total = leg_starts(self.legs)
        if total - s_here <= _DONE:
            return
        if not all(self.owns(m) and m.can_move() for m in self.motors):
            end = self.end_point()
            for motor, target in zip(self.motors, end):
                if motor.can_move() and not motor.axis.moving:
                    motor.move_to([(target, self.legs[-1].limits)])
            return
        rest: list[Leg] = []
        for s0, leg in zip(starts, self.legs):
            if s0 + leg.path.length <= s_here:
                continue
            path = SubPath(leg.path, s_here - s0) if s0 < s_here else leg.path
            rest.append(Leg(path, leg.limits))
        self.legs = rest
        self.delays = (0, 0)
        self.issued_at = now
        if self._allowed():
            self._follow(plan_path(self.legs, 0.0, now), self.motors)


class LinePaths:
    """The interpolations one line (a bank unit or a direct-mode line) starts."""

    def __init__(self, at: int = 0) -> None:
        self.pairing = Pairing(at)
        self.paths: dict[int, PairMotion] = {}

    def joining(self, x: Request, y: Request, now: int) -> PairMotion | None:
        """The path of this line that the pair continues (merged legs), if any."""
        path = self.paths.get(x.motor.id)
        if (path is not None and self.paths.get(y.motor.id) is path and path.x is x.motor
                and path.issued_at == now and all(path.owns(m) for m in path.motors)):
            return path
        return None

    def start(self, x: Request, y: Request, now: int) -> PairMotion:
        """Start the pair's leg: a new path, or the next leg of one of this line."""
        path = self.joining(x, y, now)
        if path is None:
            path = PairMotion(x.motor, y.motor, (x.delay_ns, y.delay_ns))
            self.paths[x.motor.id] = self.paths[y.motor.id] = path
        start = path.end_point()
        path.add(build_leg(x, y, start), now)
        return path

    def busy_before(self, x: Request, y: Request, now: int) -> tuple[MotorCore, ...]:
        """The pair's motors still running another motion: a bank line lets it complete
        first (4.3.2), unless the pair continues a path of this line."""
        if self.joining(x, y, now) is not None:
            return ()
        return tuple(r.motor for r in (x, y) if not r.motor.motion_done())

    def start_or_report(self, x: Request, y: Request, now: int,
                        ctx: Context | None) -> PairMotion | None:
        """:meth:`start`; a path that cannot be drawn is error00 of the X motor."""
        try:
            return self.start(x, y, now)
        except (PathError, LookupError, ValueError):
            x.motor.report_error(ctx, OutOfRangeError())
            return None

    def busy(self, motor: MotorCore) -> bool:
        """``motor`` runs a path of this line."""
        path = self.paths.get(motor.id)
        return path is not None and path.owns(motor) and motor.axis.moving


def report_leftovers(pairing: Pairing, ctx: Context | None) -> None:
    """An ``@`` without an adjacent partner on its line moves nothing: error00 of its
    motor (docs/fidelity.md "Daisy chain")."""
    for req in pairing.leftovers():
        req.motor.report_error(ctx, OutOfRangeError())


# ---------------------------------------------------------------- direct mode

def direct_selection(motor: MotorCore) -> Selection:
    """Direct mode and ladder banks use R0 or N0, whichever was written last."""
    return Selection(kind=motor.direct_interp_kind)


def direct_limits(motor: MotorCore) -> Limits | None:
    """S0 and A0 of the motor (as ``^``, 2.1.2)."""
    try:
        return motor.limits(int(motor.memory.get("S", 0)), int(motor.memory.get("A", 0)))
    except ValueError:
        return None


#: Context.extra key of the :class:`LinePairs` of a direct-mode line.
LINE_PAIRS = "@pairs"


@dataclass
class LinePairs:
    """The ``@`` of one direct-mode line, paired before the line runs (4.4), and when
    the line reaches each motor (``arrivals``, ns; empty without chain pacing)."""

    partner: dict[int, tuple[ast.Interp, int]]   # id(X statement) -> (Y statement, Y id)
    followers: set[int]                          # id(Y statement): started with its X
    alone: set[int]                              # id(statement): no adjacent partner
    arrivals: dict[int, int]


def pair_line(line: Sequence[tuple[ast.Statement, int]], on_chain: Callable[[int], bool],
              arrivals: dict[int, int]) -> LinePairs | None:
    """Pair the ``@`` (with their routed motor IDs) of a line as :class:`Pairing` does;
    ``None`` when the line has none."""
    waiting: list[tuple[ast.Interp, int]] = []
    pairs = LinePairs({}, set(), set(), arrivals)
    for stmt, motor_id in line:
        if not isinstance(stmt, ast.Interp) or not on_chain(motor_id):
            continue
        for other in waiting:
            if other[1] == motor_id:
                waiting.remove(other)
                pairs.alone.add(id(other[0]))
                break
        partner = next((w for w in waiting if abs(w[1] - motor_id) == 1), None)
        if partner is None:
            waiting.append((stmt, motor_id))
            continue
        waiting.remove(partner)
        x, y = sorted((partner, (stmt, motor_id)), key=lambda item: item[1])
        pairs.partner[id(x[0])] = y
        pairs.followers.add(id(y[0]))
    pairs.alone.update(id(stmt) for stmt, _ in waiting)
    if not (pairs.partner or pairs.alone):
        return None
    return pairs


def direct_interp(motor: MotorCore, stmt: ast.Interp, ctx: Context) -> None:
    """``@#.n`` in direct mode (2.1.2 "@.1+, @.2+"): the pair starts when the X motor's
    ``@`` runs; with chain pacing the Y motor starts when the line reaches it.

    Like a jog, a pair either of whose motors is moving (or cannot move) is not started.
    An ``@`` that is not a statement of a paired line (a branch action, a ladder bank)
    pairs with the ``@`` run at the same instant in the same context.
    """
    pairs = ctx.extra.get(LINE_PAIRS)
    key = id(stmt)
    if isinstance(pairs, LinePairs) and (key in pairs.partner or key in pairs.followers
                                         or key in pairs.alone):
        if key in pairs.alone:
            _direct_request(motor, stmt, ctx)        # error00 for a wrong type first
            motor.report_error(ctx, OutOfRangeError())
        elif key in pairs.partner:
            y_stmt, y_id = pairs.partner[key]
            partner = motor.bus.motor(y_id)
            now = motor.kernel.now
            delay = max(pairs.arrivals.get(y_id, now) - pairs.arrivals.get(motor.id, now), 0)
            x = _direct_request(motor, stmt, ctx)
            y = _direct_request(partner, y_stmt, ctx, delay) if partner is not None else None
            if x is not None and y is not None:
                _direct_start(LinePaths(now), x, y, ctx)
        return
    now = motor.kernel.now
    line = ctx.extra.get("@")
    if not isinstance(line, LinePaths) or line.pairing.at != now:
        line = ctx.extra["@"] = LinePaths(now)
    req = _direct_request(motor, stmt, ctx)
    if req is None:
        return
    pair = line.pairing.add(req)
    if pair is not None:
        _direct_start(line, *pair, ctx)


def _direct_request(motor: MotorCore, stmt: ast.Interp, ctx: Context,
                    delay_ns: int = 0) -> Request | None:
    try:
        return request(motor, stmt, direct_selection(motor), direct_limits(motor), delay_ns)
    except (MotorError, LookupError):
        motor.report_error(ctx, OutOfRangeError())
        return None


def _direct_start(line: LinePaths, x: Request, y: Request, ctx: Context) -> None:
    if not any(m.axis.moving or not m.can_move() for m in (x.motor, y.motor)):
        line.start_or_report(x, y, x.motor.kernel.now, ctx)


def message_bytes(statements: Sequence[ast.Statement], motor_id: int, default: int) -> int:
    """Bytes of the statements of a bank line for ``motor_id`` sent down the chain as
    one message: their canonical text and a separator each (ch. 3 K65 timing)."""
    from ...cml.ast import inner_motor
    return sum(len(format_statement(stmt)) + 1 for stmt in statements
               if (inner_motor(stmt) or default) == motor_id)


def end_of_line(ctx: Context) -> None:
    """Report the ``@`` of a direct-mode line left without a partner."""
    line = ctx.extra.pop("@", None)
    if isinstance(line, LinePaths):
        report_leftovers(line.pairing, ctx)


__all__ = ["Selection", "Request", "Pairing", "PairMotion", "LinePaths", "build_leg",
           "direct_interp", "end_of_line", "request", "report_leftovers", "LINE_PAIRS",
           "LinePairs", "pair_line", "message_bytes"]
