"""The servo and load model: the actual shaft motion under a command, in closed form.

A :class:`Motion` is the shaft's trajectory from one instant on, for one commanded
:class:`~coolmuscle.motor.motion.profile.Profile` and one set of :class:`Drive` parameters
(torque limit, load, stoppers, servo on or off).  It is a chain of :class:`Piece` s,
each in one mode, each closed form (:mod:`.expoly`); the switching instants are
solved, never polled.  The axis builds a new Motion whenever the command or the drive
changes (cml-users-guide.txt 2.1.1 "M": "Soon after setting M data, the motor torque
should be limited by M data").

Modes (docs/fidelity.md "Servo, load and alarms"):

* ``track``: the position loop follows the command, ``e' = v_cmd - kp·e`` (actual speed
  ``kp·e``, Pe = e); the torque is what the inertia, friction and load need (Coulomb
  friction drops out once the shaft creeps slower than V_STILL onto a standing command).  A stepper
  (``kp = inf``, CM1) follows the command exactly.
* ``sat``: the needed torque exceeds the limit; the motor gives the limit, so the shaft
  accelerates at a constant rate (a quadratic) and lags until it meets the speed the
  loop asks for.
* ``brake``: after a lag, the shaft brakes at the limit torque so as to land on the
  command's speed where the loop would have it (the braking curve u² = 2·a·ε of the
  speed and position differences), instead of overshooting.
* ``vsat``: the loop asks for more than the maximum speed (K40); the shaft runs at it
  (a load the torque limit cannot hold drags it beyond: over speed).
* ``stall``: the torque limit cannot overcome the friction and load.
* ``contact``: the shaft is held by a hard stopper; Pe grows, the torque is the limit.
* ``free``: servo off (or a stepper that lost its steps, ``lost``): only friction and
  load act, the shaft coasts to rest.  A load that drives it spins it up to the speed
  where the windings' back-EMF reaches the supply (``v_free``), where regeneration
  holds it; against a stopper it rests there.

Units: positions in pulses (raw axis coordinates), time in seconds from the motion's
origin, torques as accelerations of the total inertia (pulses/s²).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Final

from ...sim.kernel import NS_PER_S, seconds
from ...sim.memo import Key, Memo
from . import expoly as xp
from .expoly import AnyF, F
from .profile import Profile, Segment

# The module's constants are Final: compiled code then has them as C constants instead
# of looking each up in the module's dictionary at every use (docs/performance.md).
TRACK: Final = "track"
SAT: Final = "sat"
BRAKE: Final = "brake"
VSAT: Final = "vsat"
STALL: Final = "stall"
CONTACT: Final = "contact"
FREE: Final = "free"
LOST: Final = "lost"

#: Searches for a mode's end start this long after the mode began (s): no Zeno chains.
TAU_MIN: Final = 1e-9
#: Settling slower than this (pulses/s) on a standing command needs no friction torque.
V_STILL: Final = 0.5
#: A speed mismatch the torque limit would close within this time (s) is closed at once.
SNAP_TIME: Final = 1e-6
#: After this many pieces shorter than 0.1 µs in a row the solver tracks through
#: (the torque limit is exceeded by a hair for at most SLIDE seconds): no chattering.
CHATTER: Final = 8
SLIDE: Final = 1e-4
#: Relative margin by which a mode's end condition must hold (float noise at a switch).
REL_TOL: Final = 1e-9
#: Pieces one motion may hold before the model gives up saturating (a safety net).
MAX_PIECES: Final = 2000
#: The exit of a piece chosen but not yet ended (the first piece after a horizon).
OPEN: Final = "open"

Conditions = Callable[["Piece"], Sequence[AnyF] | None]
#: How a piece may end: (exit name, the functions whose first root ends it, or the
#: instant itself).
Exits = list[tuple[str, "list[AnyF] | float"]]


@dataclass(eq=False, slots=True)
class Drive:
    """What the dynamics need from the motor, the load and the machine.  Immutable by
    convention (``dataclasses.replace`` makes a changed copy)."""

    kp: float                       # position-loop gain, 1/s (inf: stepper)
    a_limit: float                  # torque limit as an acceleration, pulses/s²
    a_friction: float               # Coulomb friction as an acceleration
    a_load: float                   # constant load torque as an acceleration (signed)
    v_max: float                    # maximum speed, pulses/s
    enabled: bool = True
    wall_lo: float = -math.inf      # hard stoppers, raw pulses
    wall_hi: float = math.inf
    percent_per_accel: float = 0.0  # Ix % per pulses/s² of torque
    v_free: float = math.inf        # back-EMF speed: a driven free shaft goes no faster

    def _key(self) -> tuple[float, float, float, float, float, bool, float, float, float,
                            float]:
        return (self.kp, self.a_limit, self.a_friction, self.a_load, self.v_max,
                self.enabled, self.wall_lo, self.wall_hi, self.percent_per_accel,
                self.v_free)

    # Written out, not generated (docs/architecture.md "Fast code"): the solved motions
    # are remembered by the drive (_placed), so every move hashes one and a chain of
    # alike motors compares them.
    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Drive):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    @property
    def stepper(self) -> bool:
        return math.isinf(self.kp)


class Piece:
    """One stretch of motion in one mode; τ is local (0 at ``start``).

    Immutable in meaning once :class:`Motion` has set its ``end`` and ``exit``.  Its
    derived functions (speed, error) and their bounds are computed once, on first use,
    and kept: watchers and evaluations ask for them many times per motion (the
    arithmetic is the same as computing them afresh).  ``on_cmd``: the shaft is on its
    command (a stepper that keeps its steps: ``pos`` equals ``cmd``).

    The functions are fixed-size tuples (:data:`.expoly.F`), which compiled code keeps
    unboxed in the object; so ``_vel`` and ``_err`` are never ``None`` (an optional
    tuple would be boxed) and flags say whether they are computed yet."""

    __slots__ = ("start", "end", "mode", "pos", "cmd", "torque", "k", "s", "exit",
                 "on_cmd", "_vel", "_err", "_has_vel", "_has_err", "_bounded", "_reach_err",
                 "_reach_vel", "_reach_torque")

    def __init__(self, start: float, end: float, mode: str, pos: F, cmd: F, torque: F,
                 k: float, s: int = 0, exit: str = "", on_cmd: bool = False) -> None:
        self.start = start
        self.end = end
        self.mode = mode
        self.pos = pos
        self.cmd = cmd
        self.torque = torque
        self.k = k
        self.s = s
        self.exit = exit
        self.on_cmd = on_cmd
        self._vel: F = (0.0, 0.0, 0.0, 0.0, 0.0)
        self._err: F = (0.0, 0.0, 0.0, 0.0, 0.0)
        self._has_vel = False
        self._has_err = False
        # the bounds of |err|, |vel|, |torque| (:meth:`reach`), three numbers, not an
        # optional tuple: compiled, they stay unboxed in the object
        self._bounded = False
        self._reach_err = self._reach_vel = self._reach_torque = 0.0

    def set_vel(self, vel: F) -> None:
        """Give the speed, computed already (the same numbers as :meth:`vel`)."""
        self._vel, self._has_vel = vel, True

    def set_err(self, err: F) -> None:
        """Give the error, computed already (the same numbers as :meth:`err`)."""
        self._err, self._has_err = err, True

    def __repr__(self) -> str:
        return (f"Piece(start={self.start!r}, end={self.end!r}, mode={self.mode!r}, "
                f"pos={self.pos!r}, cmd={self.cmd!r}, torque={self.torque!r}, "
                f"k={self.k!r}, s={self.s!r}, exit={self.exit!r})")

    @property
    def duration(self) -> float:
        return self.end - self.start

    def placed(self, p0: float, cmd: F) -> Piece:
        """This piece (solved relative to where its command started) where it is: the
        shaft from ``p0``, under the absolute command ``cmd``.  The error is computed
        afresh against the command, so Pe = command - position holds in absolute terms
        and a command ends exactly on its target.  Speed and torque do not depend on
        where the axis is: they are shared."""
        pos = self.pos
        out = Piece(self.start, self.end, self.mode, (p0, pos[1], pos[2], pos[3], pos[4]),
                    cmd, self.torque, self.k, self.s, self.exit, self.on_cmd)
        out.set_vel(self.vel())
        return out

    def moved(self, shift: float, end: float) -> Piece:
        """This piece seen from an origin ``shift`` seconds later, ending at ``end`` at
        the latest (the same functions of its own τ)."""
        last = self.end - shift
        out = Piece(self.start - shift, min(last, end), self.mode, self.pos,
                    self.cmd, self.torque, self.k, self.s, self.exit, self.on_cmd)
        out._vel, out._has_vel = self._vel, self._has_vel
        out._err, out._has_err = self._err, self._has_err
        if last <= end:
            # the same stretch: the same bounds
            out._bounded, out._reach_err = self._bounded, self._reach_err
            out._reach_vel, out._reach_torque = self._reach_vel, self._reach_torque
        return out

    def vel(self) -> F:
        """The actual speed (d pos / dτ)."""
        if not self._has_vel:
            self.set_vel(xp.deriv(self.pos, self.k))
        return self._vel

    def err(self) -> F:
        """Pe = command - actual."""
        if not self._has_err:
            self.set_err(xp.sub(self.cmd, self.pos))
        return self._err

    def reach(self, what: str) -> float:
        """A bound of |err|, |vel| or |torque| (``what``) over the piece."""
        self._bound()
        index = _reach_index(what)
        return self._reach_err if index == 0 else self._reach_vel if index == 1 \
            else self._reach_torque

    def _bound(self) -> None:
        """The three bounds of :meth:`reach`, computed at the first ask."""
        if not self._bounded:
            dur = self.end - self.start
            self._reach_err = xp.abs_bound(self.err(), dur)
            self._reach_vel = xp.abs_bound(self.vel(), dur)
            self._reach_torque = xp.abs_bound(self.torque, dur)
            self._bounded = True


_REACH: Final = {"err": 0, "vel": 1, "torque": 2}


def _reach_index(what: str) -> int:
    """:data:`_REACH`'s index of ``what`` (compared, not hashed: asked by every watcher
    of every motion)."""
    if what == "err":
        return 0
    if what == "vel":
        return 1
    if what == "torque":
        return 2
    raise KeyError(what)


def _sign(x: float) -> int:
    return (x > 0.0) - (x < 0.0)


class CommandPiece:
    """One piece of a motion's command: from ``start`` to ``end`` (s from the motion's
    origin; the last is endless) the cubic ``poly`` (an :data:`.expoly.F` without its
    exponential term).  Immutable by convention; equal and hashed by its values (a
    solved motion is looked up by its command, :func:`_solved`).  An object, not a
    tuple: every target of a stream builds its command, and compiled code keeps a
    plain class's numbers unboxed where a tuple in a list is a float object each."""

    __slots__ = ("start", "end", "poly", "_hash", "_hashed")

    def __init__(self, start: float, end: float, poly: F) -> None:
        self.start = start
        self.end = end
        self.poly = poly
        self._hash = 0
        self._hashed = False            # the hash is made at the first lookup, and kept

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CommandPiece):
            return NotImplemented
        a, b = self.poly, other.poly                  # compared number by number
        return self.start == other.start and self.end == other.end and a[0] == b[0] \
            and a[1] == b[1] and a[2] == b[2] and a[3] == b[3] and a[4] == b[4]

    def __hash__(self) -> int:
        if not self._hashed:
            self._hash = hash((self.start, self.end, self.poly))
            self._hashed = True
        return self._hash

    def __repr__(self) -> str:
        return f"CommandPiece({self.start!r}, {self.end!r}, {self.poly!r})"


def command_pieces(profile: Profile, origin_ns: int,
                   memos: MotionMemos | None = None) -> list[CommandPiece]:
    """The command as pieces (start, end, cubic) from ``origin_ns`` on; the last is
    endless.

    Remembered in ``memos`` for a reused plan (the same segment tuple: planner.plan_moves)
    seen from the same offset: a repeated move builds its command once.  A hold (no
    segments: csp's command, a new position every cycle) is one constant piece, built
    faster than looked up, and is not kept."""
    segments, base = profile.segments, profile.origin_ns
    if memos is None or not segments:
        return _command_pieces(profile, origin_ns)
    key: Key = (id(segments), origin_ns - base, profile.start_state, profile.final_position,
           None if profile.end_ns is None else profile.end_ns - base)
    found = memos.commands.get(key)
    if found is not None and found[0] is segments:
        return list(found[1])
    out = _command_pieces(profile, origin_ns)
    memos.commands.put(key, (segments, tuple(out)))     # the segments held: their id stays
    return out


def _command_pieces(profile: Profile, origin_ns: int) -> list[CommandPiece]:
    off = (origin_ns - profile.origin_ns) / NS_PER_S
    out: list[CommandPiece] = []
    if profile.end_ns is not None and origin_ns >= profile.end_ns:
        return [CommandPiece(0.0, math.inf, xp.const(profile.final_position))]
    if off < 0.0:
        out.append(CommandPiece(0.0, -off, xp.const(profile.start_state[0])))
    for seg in profile.segments:
        s0, s1 = seg.start - off, seg.end - off
        if s1 <= 0.0:
            continue
        p, v, a = seg.state(max(0.0, -s0))
        out.append(CommandPiece(max(s0, 0.0), s1, (p, v, a / 2.0, seg.j / 6.0, 0.0)))
    if profile.end_ns is not None:
        last = out[-1].end if out else 0.0
        out.append(CommandPiece(last, math.inf, xp.const(profile.final_position)))
    return out


class Solution:
    """A motion's pieces where they are, with what watchers read of them: the start of
    each piece, the peak of each bound (:meth:`Motion.peak`) and the instants asked of it
    (:meth:`Motion.settled`, :meth:`Motion.within`), remembered.

    Shared by every :class:`Motion` that is the same move at the same place (a chain's
    :class:`MotionMemos`): nothing changes it but the instants it remembers, which are
    the same for every motion that asks."""

    __slots__ = ("pieces", "starts", "peaks", "instants", "unsolved")

    def __init__(self, pieces: tuple[Piece, ...], unsolved: _Unsolved | None = None) -> None:
        self.pieces = pieces
        self.starts = tuple([p.start for p in pieces])
        self.peaks = _peaks(pieces) if pieces else (0.0, 0.0, 0.0)
        #: Instants found, relative to the motion's origin (:data:`_NEVER`: none);
        #: made at the first one.
        self.instants: Memo[Key, int] | None = None
        #: What is still to solve (``None``: solved to the end).  The pieces and the
        #: peaks are then those of the part solved, and an instant not found in it is
        #: "not before the frontier" (:meth:`Motion.first_of`).
        self.unsolved = unsolved

    @property
    def frontier(self) -> float:
        """Where the solved part ends (s from the origin; ∞: solved to the end)."""
        if self.unsolved is None:
            return math.inf
        return self.pieces[-1].end if self.pieces else 0.0

    def extend(self, until: float) -> None:
        """Solve on until every piece that starts before ``until`` (s) is solved
        (∞: to the end).  The pieces are those one pass gives, to the bit."""
        rest = self.unsolved
        if rest is None:
            return
        rest.solver.resume(until)
        self.pieces = self.pieces + rest.place_new()
        self.starts = tuple([p.start for p in self.pieces])
        self.peaks = _peaks(self.pieces)
        self.instants = None                    # "never" was only "not yet solved"
        if rest.solver.done:
            self.unsolved = None


#: Instants a :class:`Solution` remembers (a repeated move asks the same few again).
INSTANTS: Final = 64
#: A remembered "never in this motion" (an instant is never before the motion's origin).
_NEVER: Final = -1


class MotionMemos:
    """What one chain's axes remember of their motion, shared by its motors (alike
    motors on alike moves reuse each other's): the planner's plans (planner.plan_moves),
    the command pieces of a plan seen from an offset, the solutions relative to the
    command's start (:func:`_solved`) and placed (:func:`_placed`), and the splices of a
    reversal (:meth:`Motion.continued`).  A hit gives the numbers a fresh computation
    gives, to the bit (tests/test_restart_at_rest.py, tests/test_servo_load.py), so the
    motion never depends on what ran before (docs/performance.md)."""

    def __init__(self, size: int = 1024) -> None:
        self.plans: Memo[Key, tuple[tuple[Segment, ...], tuple[tuple[float, int], ...]]] = \
            Memo(size)
        self.commands: Memo[Key, tuple[object, tuple[CommandPiece, ...]]] = \
            Memo(size)
        #: By what a solution depends on: the drive, the shaft's position and speed, the
        #: command (relative to its start for ``solved``).
        self.solved: Memo[Key, tuple[Piece, ...]] = Memo(size)
        self.placed: Memo[Key, Solution] = Memo(size)
        #: (id of the pieces taken from the old motion, their offset in it, its origin
        #: to the new origin, the new origin to the tail's, id of the tail's pieces) ->
        #: (those pieces, the tail's pieces, the splice); the pieces are held, so an id
        #: is never reused while it is a key.
        self.splices: Memo[Key, tuple[tuple[Piece, ...], tuple[Piece, ...], Solution]] = \
            Memo(size)

    def clear(self) -> None:
        """Forget everything (tests, benchmarks: every move planned and solved afresh)."""
        for memo in (self.plans, self.commands, self.solved, self.placed, self.splices):
            memo.clear()

    def reuse(self) -> tuple[int, int]:
        """(motions that reused a solution, motions solved) since the last clear."""
        return self.placed.hits + self.solved.hits, self.solved.misses


class Motion:
    """The shaft's motion from ``origin_ns``: pieces built at once up to an endless one
    (or up to a horizon, below).

    ``memos``: where the solution is looked up and kept (the chain's); without, the
    motion is solved afresh.

    ``horizon_ns``: the motion will most likely be replaced then (the next target of a
    stream, :meth:`.axis.Axis.follow`): it is solved only as far as the pieces that
    begin before it, the rest when something asks for it (an instant beyond, evaluated;
    :meth:`complete`).  The pieces are the same to the bit either way.  Until then the
    searches (:meth:`first_of`, :meth:`peak`) answer for the part solved, up to
    :meth:`frontier_ns`; the axis asks again there if the motion is still its own."""

    def __init__(self, profile: Profile, origin_ns: int, position: float, velocity: float,
                 drive: Drive, memos: MotionMemos | None = None,
                 solution: Solution | None = None, horizon_ns: int | None = None) -> None:
        self.profile = profile
        self.origin_ns = int(origin_ns)
        self.drive = drive
        self.kp = drive.kp
        self.memos = memos
        if solution is None:
            if horizon_ns is not None and horizon_ns > self.origin_ns:
                # solved in part, never shared: a stream's targets do not repeat
                until = (horizon_ns - self.origin_ns) / NS_PER_S
                solution = _placed(drive, float(position), float(velocity),
                                   tuple(command_pieces(profile, self.origin_ns, None)),
                                   None, until)
            else:
                solution = _placed(drive, float(position), float(velocity),
                                   tuple(command_pieces(profile, self.origin_ns, memos)),
                                   memos)
        self._use(solution)
        #: The motion the pieces from its origin on come from, in its own coordinates
        #: (:meth:`continued`; ``None``: this one).
        self._tail: Motion | None = None

    def _use(self, solution: Solution) -> None:
        self._solution = solution
        #: The pieces, in order (shared with other motions that are the same move at the
        #: same place); those solved so far while the motion is :attr:`open`.
        self.pieces = solution.pieces
        self._starts = solution.starts
        #: Where the solved part ends (s from the origin; ∞: solved to the end).
        self._frontier = solution.frontier

    @property
    def open(self) -> bool:
        """Solved only in part so far (a ``horizon_ns`` was given)."""
        return self._solution.unsolved is not None

    def frontier_ns(self) -> int | None:
        """The instant the solved part ends (``None``: solved to the end)."""
        if self._solution.unsolved is None:
            return None
        return self.origin_ns + seconds(self._frontier)

    def complete(self) -> None:
        """Solve the rest of the motion now."""
        self.cover(math.inf)

    def cover(self, rel: float) -> None:
        """Solve on until the pieces reach ``rel`` (s from the origin) at least."""
        if rel > self._frontier and self._solution.unsolved is not None:
            self._solution.extend(math.nextafter(rel, math.inf) if rel < math.inf else rel)
            self._use(self._solution)

    def cover_ns(self, t_ns: int) -> None:
        """:meth:`cover` up to the kernel time ``t_ns``."""
        self.cover((t_ns - self.origin_ns) / NS_PER_S)

    @staticmethod
    def continued(old: Motion, origin_ns: int, profile: Profile) -> Motion:
        """``old`` from ``origin_ns`` until ``profile`` begins (its command unchanged until
        then), then the motion under ``profile`` from ``old``'s state at that instant.

        The second part is solved at ``profile``'s origin, in its coordinates (the same
        solution :func:`_placed` gives, reused as such by a repeated cycle); the first
        part is ``old``'s own pieces.  A reversal that the planner starts from rest at
        the end of a decelerating command (``Axis.move``) is solved this way."""
        at = profile.origin_ns
        memos = old.memos
        old.complete()
        position, velocity = old.exact_state(at)
        tail = Motion(profile, at, position, velocity, old.drive, memos)
        motion = Motion(profile, at, position, velocity, old.drive, memos,
                        tail._solution)          # its own pieces below
        motion.origin_ns = int(origin_ns)
        motion._tail = tail
        # The spliced pieces depend only on old's pieces from now on, tail's pieces and
        # the offsets: a repeated cycle splices the same ones again (memos.splices).  When
        # old is a splice too and now is on its tail, its pieces from now on are its tail's
        # (a solution, kept by _placed) moved by old's own offset.
        source: tuple[Piece, ...] | None = old.pieces
        offset = -1
        if old._tail is not None:
            source = None
            if motion.origin_ns >= old._tail.origin_ns:
                source, offset = old._tail.pieces, old._tail.origin_ns - old.origin_ns
        key: Key = (id(source), offset, motion.origin_ns - old.origin_ns, at - motion.origin_ns,
               id(tail.pieces))
        if source is not None and memos is not None:
            found = memos.splices.get(key)
            if found is not None and found[0] is source and found[1] is tail.pieces:
                motion._use(found[2])
                return motion
        shift_old = (motion.origin_ns - old.origin_ns) / NS_PER_S
        cut = (at - motion.origin_ns) / NS_PER_S
        pieces = [piece.moved(shift_old, cut) for piece in old.pieces
                  if piece.end - shift_old > 0.0 and piece.start - shift_old < cut]
        pieces += [piece.moved(-cut, math.inf) for piece in tail.pieces]
        spliced = Solution(tuple(pieces))
        motion._use(spliced)
        if source is not None and memos is not None:
            memos.splices.put(key, (source, tail.pieces, spliced))
        return motion

    def exact_state(self, t_ns: int) -> tuple[float, float]:
        """(position, speed) at ``t_ns`` in the coordinates of the solution it is on:
        the same numbers for the same instant of a repeated motion, wherever the motion
        was spliced (:meth:`continued`)."""
        tail = self._tail
        if tail is not None and t_ns >= tail.origin_ns:
            return tail.exact_state(t_ns)
        return self.position_at(t_ns), self.velocity_at(t_ns)

    # -- evaluation -----------------------------------------------------------
    def _rel(self, t_ns: int) -> float:
        return (t_ns - self.origin_ns) / NS_PER_S

    def _locate(self, t_ns: int) -> tuple[Piece, float]:
        rel = (t_ns - self.origin_ns) / NS_PER_S
        if rel < 0.0:
            rel = 0.0
        if rel >= self._frontier:
            nxt = self._solution.unsolved.next if self._solution.unsolved is not None \
                else None
            if rel == self._frontier and nxt is not None:
                return nxt, 0.0                 # where the next piece begins: known
            self.cover(rel)
        i = bisect_right(self._starts, rel) - 1
        piece = self.pieces[i if i > 0 else 0]
        return piece, rel - piece.start

    def position_at(self, t_ns: int) -> float:
        """Actual shaft position (raw pulses)."""
        piece, tau = self._locate(t_ns)
        return xp.value(piece.pos, piece.k, tau)

    def velocity_at(self, t_ns: int) -> float:
        """Actual speed (raw pulses/s)."""
        piece, tau = self._locate(t_ns)
        return xp.value(piece.vel(), piece.k, tau)

    def command_at(self, t_ns: int) -> float:
        """The command; with the servo off the command follows the shaft."""
        if not self.drive.enabled:
            return self.position_at(t_ns)
        piece, tau = self._locate(t_ns)
        return xp.value(piece.cmd, piece.k, tau)

    def error_at(self, t_ns: int) -> float:
        """Pe = command - actual (raw pulses); 0 with the servo off."""
        if not self.drive.enabled:
            return 0.0
        piece, tau = self._locate(t_ns)
        return xp.value(piece.err(), piece.k, tau)

    def actual_velocity_at(self, t_ns: int) -> float:
        return self.velocity_at(t_ns)

    def torque_at(self, t_ns: int) -> float:
        """Motor torque as an acceleration (pulses/s², signed raw); 0 with the servo
        off (no current: ``?98`` reads 0 then, the thermal model does not heat)."""
        if not self.drive.enabled:
            return 0.0
        piece, tau = self._locate(t_ns)
        return xp.value(piece.torque, piece.k, tau)

    def torque_percent_at(self, t_ns: int) -> float:
        """Motor torque, % of rated (signed, raw direction)."""
        return self.torque_at(t_ns) * self.drive.percent_per_accel

    def mode_at(self, t_ns: int) -> str:
        return self._locate(t_ns)[0].mode

    # -- solved instants --------------------------------------------------------
    def to_ns(self, piece: Piece, tau: float) -> int:
        return self.origin_ns + seconds(piece.start + tau)

    def reach(self, piece: Piece, what: str) -> float:
        """A bound of |err|, |vel| or |torque| (``what``) over a piece (cached)."""
        return piece.reach(what)

    def peak(self, what: str) -> float:
        """The largest :meth:`reach` of any piece: a bound over the whole motion.

        A watcher whose threshold is at or above it skips every piece, so it can
        answer "never" without walking them."""
        index, peaks = _reach_index(what), self._solution.peaks
        return peaks[0] if index == 0 else peaks[1] if index == 1 else peaks[2]

    def settled(self, window: float, after_ns: int) -> int | None:
        """The first instant >= ``after_ns`` where |Pe| <= ``window`` (``None``: never in
        this motion).  Remembered with the solution: a repeated move asks it again."""
        tail = self._tail
        if tail is not None and after_ns >= tail.origin_ns:
            return tail.settled(window, after_ns)
        def inside(piece: Piece) -> list[AnyF]:
            e = piece.err()
            return [xp.sub(xp.const(window), e), xp.sub(e, xp.const(-window))]
        return self._instant((window, after_ns - self.origin_ns), after_ns, inside)

    def within(self, center: float, window: float, after_ns: int) -> int | None:
        """The first instant >= ``after_ns`` where the actual position is within
        ``window`` of ``center`` (ch. 3 K55 in-position; ``None``: never in this motion)."""
        tail = self._tail
        if tail is not None and after_ns >= tail.origin_ns:
            return tail.within(center, window, after_ns)
        solution = self._solution
        if solution.unsolved is not None:           # sought, not remembered (_instant)
            return self._first_within(center, window, after_ns)
        key: Key = ("within", center, window, after_ns - self.origin_ns)
        found = self._recalled(key)
        if found is None:
            found = self._remember(key, self._first_within(center, window, after_ns))
        return None if found == _NEVER else self.origin_ns + found

    def _first_within(self, center: float, window: float, after_ns: int) -> int | None:
        """:meth:`first_of` for :meth:`within`, written out (every target of a stream
        asks it): a piece whose position stays ``window`` or more from ``center`` by its
        bound (:func:`xp.spread`) is passed without seeking roots, where none would be
        found; the others are searched with the same conditions.

        The two conditions (below ``center + window``, above ``center - window``) add
        up to ``2 * window``: where one fails the other holds.  So a position inside at
        the start of the search is the answer there, and one outside waits for the
        condition it fails alone (one root search, not two)."""
        if not window > 0.0:                        # both never hold together
            return None
        rel = max(0.0, self._rel(after_ns))
        i = max(0, bisect_right(self._starts, rel) - 1)
        for piece in self.pieces[i:]:
            pos = piece.pos
            duration = piece.duration
            if abs(pos[0] - center) - xp.spread(pos, duration) >= window:
                continue
            start = max(0.0, rel - piece.start)
            if start >= duration:
                continue
            off = xp.sub(pos, xp.const(center))
            below, above = xp.sub(xp.const(window), off), xp.sub(off, xp.const(-window))
            if not xp.value(below, piece.k, start) > 0.0:
                tau = xp.first_true([below], piece.k, start, duration)
            elif not xp.value(above, piece.k, start) > 0.0:
                tau = xp.first_true([above], piece.k, start, duration)
            else:
                tau = start                         # inside already
            if tau is not None:
                at = self.origin_ns + math.ceil((piece.start + tau) * NS_PER_S)
                return max(after_ns, at)
        return None

    def _instant(self, key: Key, after_ns: int, inside: Conditions) -> int | None:
        """The first instant >= ``after_ns`` where ``inside`` holds, remembered with the
        solution under ``key``.  A motion solved in part is not shared and is replaced
        soon (a stream's next target): its instants are sought, not remembered."""
        if self._solution.unsolved is not None:
            return self.first_of(after_ns, (inside,))
        found = self._recalled(key)
        if found is None:
            found = self._remember(key, self.first_of(after_ns, (inside,)))
        return None if found == _NEVER else self.origin_ns + found

    def _recalled(self, key: Key) -> int | None:
        """The instant remembered under ``key`` (relative, or :data:`_NEVER`), if any."""
        instants = self._solution.instants
        return None if instants is None else instants.get(key)

    def _remember(self, key: Key, at: int | None) -> int:
        """Keep the instant ``at`` found for ``key``; the value :meth:`_recalled` gives."""
        solution = self._solution
        instants = solution.instants
        if instants is None:
            instants = solution.instants = Memo(INSTANTS)
        return instants.put(key, _NEVER if at is None else at - self.origin_ns)

    def span(self, piece: Piece) -> tuple[float, float]:
        """Bounds (lowest, highest) of the actual position over a piece."""
        spread = xp.spread(piece.pos, piece.duration)
        return piece.pos[0] - spread, piece.pos[0] + spread

    def first(self, after_ns: int, *alternatives: Conditions,
              horizon_ns: int | None = None,
              skip: Callable[[Piece], bool] | None = None,
              accept: Callable[[Piece], bool] | None = None) -> int | None:
        """First kernel time >= ``after_ns`` where, for one alternative, every condition
        it gives for the piece is > 0 (``None`` from a piece: not there).  Pieces for
        which ``skip`` is true are known not to qualify; pieces for which ``accept`` is
        true are known to qualify all along (a bound says so: no roots are sought).  The
        instant is rounded up to the next nanosecond, so the condition already holds then."""
        return self.first_of(after_ns, alternatives, horizon_ns, skip, accept)

    def first_of(self, after_ns: int, alternatives: Sequence[Conditions],
                 horizon_ns: int | None = None,
                 skip: Callable[[Piece], bool] | None = None,
                 accept: Callable[[Piece], bool] | None = None) -> int | None:
        """:meth:`first` with the alternatives as one sequence and no keywords: compiled
        code calls it directly (a call with ``*`` and keywords goes through the generic
        call protocol: 1 % of a csp axis-cycle, docs/performance.md).  On a motion solved
        in part, ``None`` means not before :meth:`frontier_ns` (the axis asks again
        there)."""
        rel = max(0.0, self._rel(after_ns))
        i = max(0, bisect_right(self._starts, rel) - 1)
        for piece in self.pieces[i:]:
            if horizon_ns is not None and self.to_ns(piece, 0.0) > horizon_ns:
                return None
            if skip is not None and skip(piece):
                continue
            a = max(0.0, rel - piece.start)
            if accept is not None and a < piece.end - piece.start and accept(piece):
                at = self.origin_ns + math.ceil((piece.start + a) * NS_PER_S)
                return max(after_ns, at)
            best: float | None = None
            for alt in alternatives:
                conds = alt(piece)
                if conds is None:
                    continue
                tau = xp.first_true(conds, piece.k, a, piece.duration)
                if tau is not None and (best is None or tau < best):
                    best = tau
            if best is not None:
                at = self.origin_ns + math.ceil((piece.start + best) * NS_PER_S)
                return max(after_ns, at)
        return None


def _solved(drive: Drive, position: float, velocity: float,
            cmd: tuple[CommandPiece, ...],
            memos: MotionMemos | None) -> tuple[Piece, ...]:
    """The pieces of a motion relative to the command's position at its origin.  The
    solution depends on nothing else, so a machine that repeats a cycle solves each of its
    moves once (``memos``, docs/performance.md); a hit and a miss give the same numbers."""
    key: Key = (drive, position, velocity, cmd)
    if memos is not None:
        found = memos.solved.get(key)
        if found is not None:
            return found
    solver = _Solver(drive, list(cmd))
    solver._build(position, velocity)
    pieces = tuple(solver.pieces)
    if memos is not None:
        memos.solved.put(key, pieces)
    return pieces


def _placed(drive: Drive, position: float, velocity: float,
            cmd: tuple[CommandPiece, ...], memos: MotionMemos | None,
            until: float = math.inf) -> Solution:
    """The pieces of a motion where it is: :func:`_solved` moved to the command's
    position at the motion's origin (kept in ``memos`` too: a cycle repeats its moves in
    place).  With ``until`` (s), only the pieces that start before it are solved, the
    rest when asked for (:meth:`Solution.extend`); such a solution is not kept."""
    lazy = until != math.inf
    key: Key = ()
    if memos is not None and not lazy:
        key = (drive, position, velocity, cmd)
        found = memos.placed.get(key)
        if found is not None:
            return found
    placement = _Placement(drive, cmd)
    ref = placement.ref
    rel_cmd = [CommandPiece(c.start, c.end, (c.poly[0] - ref, c.poly[1], c.poly[2],
                                             c.poly[3], c.poly[4])) for c in cmd]
    if lazy:
        solver = _Solver(placement.rel_drive, rel_cmd)
        solver._build(position - ref, velocity, until)
        rest = _Unsolved(solver, placement)
        return Solution(rest.place_new(), rest)
    solved = _solved(placement.rel_drive, position - ref, velocity, tuple(rel_cmd), memos)
    solution = Solution(tuple([placement.place(piece) for piece in solved]))
    if memos is not None:
        memos.placed.put(key, solution)
    return solution


class _Placement:
    """How the pieces solved relative to the command's position at the motion's origin
    are put where the shaft is (:func:`_placed`), one after another."""

    __slots__ = ("drive", "cmd", "ref", "rel_drive", "_ci")

    def __init__(self, drive: Drive, cmd: tuple[CommandPiece, ...]) -> None:
        self.drive = drive
        self.cmd = cmd
        self.ref = ref = cmd[0].poly[0]
        self.rel_drive = drive
        if drive.wall_lo != -math.inf or drive.wall_hi != math.inf:
            self.rel_drive = replace(drive, wall_lo=drive.wall_lo - ref,
                                     wall_hi=drive.wall_hi - ref)
        self._ci = 0

    def place(self, piece: Piece) -> Piece:
        """``piece`` where it is: pieces are placed in order of their start."""
        cmd, drive, rel_drive = self.cmd, self.drive, self.rel_drive
        t = piece.start
        ci = self._ci
        while ci < len(cmd) - 1 and cmd[ci].end <= t:    # the command piece it began in
            ci += 1
        self._ci = ci
        began = cmd[ci]
        c_start, c_poly = began.start, began.poly
        p0 = piece.pos[0]
        if p0 == rel_drive.wall_hi:                      # at a stopper: exactly there
            p0 = drive.wall_hi
        elif p0 == rel_drive.wall_lo:
            p0 = drive.wall_lo
        else:
            p0 += self.ref
        if piece.exit == "" and piece.mode == STALL:     # the safety net's hold
            shown = cmd[-1].poly
        else:
            shown = xp.shift(c_poly, 0.0, t - c_start)
        if piece.mode == FREE and not drive.enabled:     # servo off: the command follows
            c = piece.cmd
            shown = (p0, c[1], c[2], c[3], c[4])
        elif piece.on_cmd:                               # a stepper on its command
            p0 = shown[0]
        return piece.placed(p0, shown)


class _Unsolved:
    """The part of a motion not solved yet: the solver where it stopped, and the next
    piece (chosen, placed, its end not yet sought: what the motion is at the instant it
    begins)."""

    __slots__ = ("solver", "placement", "placed", "next")

    def __init__(self, solver: _Solver, placement: _Placement) -> None:
        self.solver = solver
        self.placement = placement
        self.placed = 0                 # the solver's pieces placed so far
        self.next: Piece | None = None

    def place_new(self) -> tuple[Piece, ...]:
        """The pieces the solver finished since the last call, placed; and the next."""
        solver, placement = self.solver, self.placement
        new = tuple([placement.place(piece) for piece in solver.pieces[self.placed:]])
        self.placed = len(solver.pieces)
        chosen = solver.next
        self.next = None if chosen is None else placement.place(chosen)
        return new


def _peaks(pieces: Sequence[Piece]) -> tuple[float, float, float]:
    """:meth:`Motion.peak` of each kind (in :data:`_REACH`'s order), as max() over the
    pieces, in one pass."""
    first = pieces[0]
    first._bound()
    top_err, top_vel, top_torque = first._reach_err, first._reach_vel, first._reach_torque
    for piece in pieces:
        piece._bound()
        b_err, b_vel, b_torque = piece._reach_err, piece._reach_vel, piece._reach_torque
        if b_err > top_err:
            top_err = b_err
        if b_vel > top_vel:
            top_vel = b_vel
        if b_torque > top_torque:
            top_torque = b_torque
    return (top_err, top_vel, top_torque)


class _Solver:
    """Builds the pieces of one motion, in coordinates relative to the command's
    position at the motion's origin (so a repeated move is solved once: :func:`_solved`)."""

    def __init__(self, drive: Drive, cmd: list[CommandPiece]) -> None:
        self.drive = drive
        self.pieces: list[Piece] = []
        # math.isfinite written as comparisons: compiled, it is a generic call
        self._walled = -math.inf < drive.wall_lo < math.inf or -math.inf < drive.wall_hi < math.inf
        self._is_stepper = drive.stepper
        self._exp_tau_min = math.exp(-drive.kp * TAU_MIN)     # e^{-kτ} at TAU_MIN (tracking)
        self._cmd = cmd
        #: Where the next piece starts: time (s), state, command piece, how the last
        #: one ended, and how many tiny pieces came in a row (no chattering).
        self._t, self._p, self._v, self._ci = 0.0, 0.0, 0.0, 0
        self._kind_prev, self._mode_prev, self._s_prev, self._tiny = "", "", 0, 0
        #: The next piece chosen, not yet ended (``None``: none chosen), its exits, the
        #: longest it may last and why it would end then (attributes of their own, not a
        #: tuple: compiled, the numbers stay unboxed).
        self.next: Piece | None = None
        self._next_exits: Exits = []
        self._next_end = 0.0
        self._next_kind = ""
        #: Solved to the end (the last piece is endless, or the safety net's).
        self.done = False

    # -- building ---------------------------------------------------------------
    def _build(self, p: float, v: float, until: float = math.inf) -> None:
        """Solve from the state (``p``, ``v``) at the command's start: every piece that
        starts before ``until`` (s; all of them by default), and the one after them
        chosen (:attr:`next`: its functions, not yet its end)."""
        self._p, self._v = p, v
        self.resume(until)

    def resume(self, until: float = math.inf) -> None:
        """Go on solving: finish the pieces that start before ``until``.  The pieces are
        those one pass to the end gives, to the bit: each is chosen and ended by the
        same steps, whenever the next one is asked for."""
        while not self.done:
            if self.next is None:
                if len(self.pieces) >= MAX_PIECES:
                    self._append(_rest_piece(self._t, self._p, self._cmd[-1].poly, self.drive))
                    self.done = True
                    return
                self._open()
            if self._t >= until:
                return
            self._close()

    def _open(self) -> None:
        """Choose the next piece: its mode and functions from the state where the last
        ended (:attr:`next`)."""
        t, p, v = self._t, self._p, self._v
        ci = self._ci
        while self._cmd[ci].end <= t:
            ci += 1
        self._ci = ci
        now_cmd = self._cmd[ci]
        c_start, c_end, c_poly = now_cmd.start, now_cmd.end, now_cmd.poly
        cmd = xp.shift(c_poly, 0.0, t - c_start)
        end, kind = c_end - t, "command"
        if self._tiny >= CHATTER and self.drive.enabled and not self.drive.stepper:
            # a sliding edge between tracking and the limit: track through it
            piece, exits = self._track(t, p, cmd, end)
            exits = [x for x in exits if x[0] != "limit"]
            end, kind, self._tiny = min(end, SLIDE), "slide", 0
        elif self._kind_prev == "brake" or (self._kind_prev == "vzero"
                                           and self._mode_prev == BRAKE):
            # braking onto the command's speed goes on through zero speed (only the
            # friction turns round): the command may be running the other way
            piece, exits = self._brake(t, p, v, cmd, self._s_prev)
        else:
            piece, exits = self._choose(t, p, v, cmd, c_end - t)
        piece.exit = OPEN
        self.next, self._next_exits, self._next_end, self._next_kind = piece, exits, end, kind

    def _close(self) -> None:
        """Find where the chosen piece ends (the first of its exits) and take it."""
        piece = self.next
        assert piece is not None
        exits, end, kind = self._next_exits, self._next_end, self._next_kind
        self.next = None
        for name, conds in exits:
            if isinstance(conds, float):
                tau: float | None = max(conds, min(TAU_MIN, end / 2.0))
            else:
                conds = [_strict(c) for c in conds]
                tau = xp.first_true(conds, piece.k, min(TAU_MIN, end / 2.0), end)
            if tau is not None and tau < end:
                end, kind = tau, name
        t = self._t
        piece.end, piece.exit = t + end, kind     # a fresh piece: finished in place
        self._append(piece)
        if math.isinf(end):
            self.done = True
            return
        self._tiny = self._tiny + 1 if end < 1e-7 else 0
        self._p, self._v = self._after(piece, end, kind)
        self._t = piece.end
        self._kind_prev, self._mode_prev, self._s_prev = kind, piece.mode, piece.s

    def _append(self, piece: Piece) -> None:
        self.pieces.append(piece)

    def _after(self, piece: Piece, tau: float, kind: str) -> tuple[float, float]:
        """The state where a piece ends, with the exit's exact values."""
        if kind == "wall_hi":
            return self.drive.wall_hi, 0.0
        if kind == "wall_lo":
            return self.drive.wall_lo, 0.0
        p = xp.value(piece.pos, piece.k, tau)
        if kind == "vzero":
            return p, 0.0
        return p, xp.value(piece.vel(), piece.k, tau)

    # -- choosing a mode ------------------------------------------------------------
    def _choose(self, t: float, p: float, v: float, cmd: F,
                dur: float = math.inf) -> tuple[Piece, Exits]:
        d = self.drive
        if not d.enabled:
            return self._free(t, p, v, cmd, FREE, 0)
        wall = _wall_side(p, d) if self._walled else 0
        if wall:
            e_probe = xp.value(cmd, 0.0, TAU_MIN) - (p + v * TAU_MIN)
            if wall * e_probe > 0.0 and wall * v >= 0.0:
                return self._contact(t, wall, cmd)
        if self._is_stepper:
            return self._stepper(t, p, v, cmd, dur)
        e0 = cmd[0] - p
        vref = max(-d.v_max, min(d.v_max, d.kp * e0))
        # two max() of two: compiled, max() of three is a generic call (the same value)
        if abs(v - vref) <= max(max(1e-6 * abs(v), SNAP_TIME * d.a_limit), 1e-9):
            track = self._track(t, p, cmd, dur)
            piece = track[0]
            # err() and the values at TAU_MIN written out (xp.sub, xp.value: same arithmetic)
            pos, x = piece.pos, self._exp_tau_min
            err = (cmd[0] - pos[0], cmd[1] - pos[1], cmd[2] - pos[2], cmd[3] - pos[3],
                   cmd[4] - pos[4])
            piece.set_err(err)
            c0, c1, c2, c3, cd = err
            e_t = c0 + TAU_MIN * (c1 + TAU_MIN * (c2 + TAU_MIN * c3))
            if cd:
                e_t = e_t + cd * x
            if d.kp * abs(e_t) > d.v_max:
                return self._vsat(t, p, cmd, _sign(e_t))
            c0, c1, c2, c3, cd = piece.torque
            torque = c0 + TAU_MIN * (c1 + TAU_MIN * (c2 + TAU_MIN * c3))
            if cd:
                torque = torque + cd * x
            if abs(torque) <= d.a_limit:
                return track
            return self._sat(t, p, v, cmd, _sign(torque))
        return self._sat(t, p, v, cmd, _sign(vref - v))

    def _walls(self, pos: F) -> Exits:
        d = self.drive
        out: Exits = []
        if math.isfinite(d.wall_hi):
            out.append(("wall_hi", [xp.sub(pos, xp.const(d.wall_hi))]))
        if math.isfinite(d.wall_lo):
            out.append(("wall_lo", [xp.sub(xp.const(d.wall_lo), pos)]))
        return out

    def _track(self, t: float, p: float, cmd: F, dur: float) -> tuple[Piece, Exits]:
        """First-order tracking of the command from error cmd(0) - p.

        The hot path of every motion: the expoly operations (sub, deriv, plus) are
        written out on the 5-tuples, with the same arithmetic."""
        d, k = self.drive, self.drive.kp
        q0, q1, q2, q3, q4 = cmd
        c2 = 3.0 * q3 / k
        c1 = (2.0 * q2 - 2.0 * c2) / k
        c0 = (q1 - c1) / k
        ed = (q0 - p) - c0
        e: F = (c0, c1, c2, 0.0, ed)
        pos: F = (q0 - c0, q1 - c1, q2 - c2, q3 - 0.0, q4 - ed)            # cmd - e
        # _stretch_sign(e, k, dur) written out (the value at the probe as xp.value)
        lo = min(TAU_MIN, dur / 2.0)
        found = xp.roots5(e, k, lo, dur)
        if found:
            turn: float | None = found[0]
            probe = (lo + found[0]) / 2.0
        else:
            turn = None
            probe = (lo + (dur if dur != math.inf else lo + 2.0)) / 2.0
        ep = c0 + probe * (c1 + probe * (c2 + probe * 0.0))
        if ed:
            ep = ep + ed * math.exp(-k * probe)
        sgn = (ep > 0.0) - (ep < 0.0)
        still = False
        if sgn and q1 == q2 == q3 == 0.0:
            # settling on a standing command: once creeping, static friction holds
            if abs(k * ed) <= V_STILL:
                sgn, turn = 0, None
            else:
                still = True
        vel: F = (pos[1], 2.0 * pos[2], 3.0 * pos[3], 0.0, -k * pos[4])   # pos'
        load = sgn * d.a_friction + d.a_load
        torque: F = (vel[1] + load, 2.0 * vel[2], 3.0 * vel[3], 0.0, -k * vel[4])  # pos'' + load
        exits = self._walls(pos) if self._walled else []
        if xp.abs_bound(torque, dur) > d.a_limit:              # _beyond("limit", ...)
            exits += _beyond("limit", torque, dur, d.a_limit)
        kev = (c0 * k, c1 * k, c2 * k, 0.0 * k, ed * k)
        if xp.abs_bound(kev, dur) > d.v_max:                    # _beyond("vmax", ...)
            exits += _beyond("vmax", kev, dur, d.v_max)
        if still:
            exits.append(("still", [xp.plus(xp.scale(e, -sgn * k), V_STILL)]))
        if turn is not None:
            exits.append(("vzero", turn))
        piece = Piece(t, math.inf, TRACK, pos, cmd, torque, k)
        piece.set_vel(vel)
        return piece, exits

    def _sat(self, t: float, p: float, v: float, cmd: F, s: int) -> tuple[Piece, Exits]:
        """The torque limit in direction ``s``: constant acceleration, the shaft lags."""
        d = self.drive
        drive_force = s * d.a_limit - d.a_load
        if v == 0.0 and abs(drive_force) <= d.a_friction:
            return self._held(t, p, cmd, STALL, s)
        sgn = _sign(v) or _sign(drive_force)
        acc = drive_force - sgn * d.a_friction
        side = _wall_side(p, d) if self._walled else 0
        if side and side * v >= 0.0 and side * acc > 0.0:
            # the load beats the limit and pins the shaft on a stopper: a stall there
            return self._held(t, d.wall_hi if side > 0 else d.wall_lo, cmd, STALL, s)
        pos: F = (p, v, acc / 2.0, 0.0, 0.0)
        vel = xp.deriv(pos, 0.0)
        e = xp.sub(cmd, pos)
        exits = self._walls(pos) + [
            ("track", [xp.scale(xp.sub(vel, xp.scale(e, d.kp)), float(s))]),
            ("vzero", [xp.scale(vel, -float(sgn))]),
        ] + self._brake_exit(pos, cmd, s)
        if abs(s * d.a_friction + d.a_load) <= d.a_limit:     # it can hold the top speed
            exits.append(("vmax", [xp.sub(xp.scale(vel, float(s)), xp.const(d.v_max))]))
        return Piece(t, math.inf, SAT, pos, cmd, xp.const(s * d.a_limit), 0.0, s), exits

    def _braking(self, s: int) -> float:
        """Relative deceleration available when braking a catch-up in direction ``s``."""
        d = self.drive
        return d.a_limit + d.a_friction + s * d.a_load

    def _brake_exit(self, pos: F, cmd: F, s: int) -> Exits:
        """Where braking at the limit lands exactly on the loop's steady lag."""
        a_b = self._braking(s)
        if a_b <= 0.0:
            return []
        v_cmd = xp.deriv(cmd, 0.0)
        u = xp.sub(xp.deriv(pos, 0.0), v_cmd)
        eps = xp.sub(xp.sub(cmd, pos), xp.scale(v_cmd, 1.0 / self.drive.kp))
        curve = xp.sub_any(xp.mul(u, u), xp.scale(eps, 2.0 * a_b * s))
        return [("brake", [xp.scale(u, float(s)), curve])]

    def _brake(self, t: float, p: float, v: float, cmd: F, s: int) -> tuple[Piece, Exits]:
        """Braking at the limit torque (against ``s``) onto the command's speed."""
        d = self.drive
        sgn = _sign(v)
        if not sgn:
            pull = -s * d.a_limit - d.a_load
            if abs(pull) <= d.a_friction:               # the limit cannot move it: held
                return self._choose(t, p, v, cmd)
            sgn = _sign(pull)
        acc = -s * d.a_limit - sgn * d.a_friction - d.a_load
        pos: F = (p, v, acc / 2.0, 0.0, 0.0)
        vel = xp.deriv(pos, 0.0)
        u = xp.sub(vel, xp.deriv(cmd, 0.0))
        exits = self._walls(pos) + [("landed", [xp.scale(u, -float(s))]),
                                    ("vzero", [xp.scale(vel, -float(sgn))])]
        # Braking through zero speed onto a command faster than the top speed (K56
        # raised, S beyond it) would otherwise accelerate the shaft past v_max: the
        # modes after it then chatter (sat -> track -> vmax) until MAX_PIECES.
        exits.append(("vmax", [xp.sub(xp.scale(vel, float(sgn)), xp.const(d.v_max))]))
        return Piece(t, math.inf, BRAKE, pos, cmd, xp.const(-s * d.a_limit), 0.0, s), exits

    def _vsat(self, t: float, p: float, cmd: F, s: int) -> tuple[Piece, Exits]:
        d = self.drive
        pos: F = (p, s * d.v_max, 0.0, 0.0, 0.0)
        e = xp.sub(cmd, pos)
        torque = xp.const(s * d.a_friction + d.a_load)
        exits = self._walls(pos) + [
            ("track", [xp.sub(xp.const(d.v_max), xp.scale(e, s * d.kp))])
        ] + self._brake_exit(pos, cmd, s)
        return Piece(t, math.inf, VSAT, pos, cmd, torque, 0.0, s), exits

    def _held(self, t: float, p: float, cmd: F, mode: str, s: int) -> tuple[Piece, Exits]:
        """Standing still at the limit torque (stall, contact) until Pe turns round."""
        pos = xp.const(p)
        exits: Exits = [("release", [xp.scale(xp.sub(cmd, pos), -float(s))])]
        torque = xp.const(s * self.drive.a_limit)
        return Piece(t, math.inf, mode, pos, cmd, torque, 0.0, s), exits

    def _contact(self, t: float, side: int, cmd: F) -> tuple[Piece, Exits]:
        d = self.drive
        return self._held(t, d.wall_hi if side > 0 else d.wall_lo, cmd, CONTACT, side)

    def _free(self, t: float, p: float, v: float, cmd: F, mode: str,
              s: int) -> tuple[Piece, Exits]:
        """No motor torque: friction and load only (servo off, lost steps).

        A load that drives the shaft spins it up to ``v_free``, the speed at which the
        windings' back-EMF reaches the supply: beyond it they feed current back through
        the driver, and that braking holds the shaft there (above it at the start, say
        freed by an over speed alarm, it is brought down to it at once).  Driven onto a
        stopper the shaft rests against it (docs/fidelity.md "Servo, load and alarms")."""
        d = self.drive
        if v == 0.0 and abs(d.a_load) <= d.a_friction:
            acc, sgn = 0.0, 0
        else:
            sgn = _sign(v) or -_sign(d.a_load)
            acc = -d.a_load - sgn * d.a_friction
        top = d.v_free
        if sgn and abs(v) > top:
            v = sgn * top                                   # regeneration brakes it
        driven = sgn != 0 and acc * sgn > 0.0
        if driven and abs(v) >= top * (1.0 - REL_TOL):
            v, acc = sgn * top, 0.0                         # held at the back-EMF speed
        side = _wall_side(p, d) if self._walled else 0
        if side and side * v >= 0.0 and side * acc > 0.0:   # pressed onto a stopper
            p, v, acc, sgn, driven = (d.wall_hi if side > 0 else d.wall_lo), 0.0, 0.0, 0, False
        pos: F = (p, v, acc / 2.0, 0.0, 0.0)
        vel = xp.deriv(pos, 0.0)
        exits = self._walls(pos) if sgn else []
        if sgn and not driven:
            exits.append(("vzero", [xp.scale(vel, -float(sgn))]))
        if driven and acc != 0.0 and math.isfinite(top):
            exits.append(("vfree", [xp.plus(xp.scale(vel, float(sgn)), -top)]))
        if mode == LOST:
            e = xp.sub(cmd, pos)
            exits.append(("relock", [xp.scale(e, -float(s))]))
        shown = xp.const(s * d.a_limit) if mode == LOST else xp.ZERO
        if not d.enabled:
            cmd = pos
        return Piece(t, math.inf, mode, pos, cmd, shown, 0.0, s), exits

    def _stepper(self, t: float, p: float, v: float, cmd: F,
                 dur: float) -> tuple[Piece, Exits]:
        """CM1: exactly on the command within the torque limit, else steps are lost."""
        d = self.drive
        e0 = cmd[0] - p
        if abs(e0) > 1e-6 * max(1.0, abs(p)):
            return self._free(t, p, v, cmd, LOST, _sign(e0))
        vel = xp.deriv(cmd, 0.0)
        sgn, turn = _stretch_sign(vel, 0.0, dur)
        torque = xp.plus(xp.deriv(vel, 0.0), sgn * d.a_friction + d.a_load)
        if abs(xp.value(torque, 0.0, TAU_MIN)) > d.a_limit:
            return self._free(t, cmd[0], v, cmd, LOST, _sign(xp.value(vel, 0.0, TAU_MIN)))
        exits = self._walls(cmd) + _beyond("limit", torque, dur, d.a_limit)
        if turn is not None:
            exits.append(("vzero", turn))
        return Piece(t, math.inf, TRACK, cmd, cmd, torque, 0.0, on_cmd=True), exits


def _strict(f: AnyF) -> AnyF:
    """``f - tol``: a mode ends only when its condition holds beyond float noise."""
    top = 1.0                        # max(1.0, max(f), -min(f)), without boxing
    if len(f) == 5:                  # a piece's function (unboxed when compiled)
        c0, c1, c2, c3, d = f
        top = _top(_top(_top(_top(_top(top, c0), c1), c2), c3), d)
        return (c0 - REL_TOL * top, c1, c2, c3, d)
    for c in f:
        if c > top:
            top = c
        if -c > top:
            top = -c
    return (f[0] - REL_TOL * top,) + f[1:]


def _top(top: float, c: float) -> float:
    """One step of :func:`_strict`'s loop."""
    if c > top:
        top = c
    if -c > top:
        top = -c
    return top


def _wall_side(p: float, d: Drive) -> int:
    tol = 1e-9 * max(1.0, abs(p))
    if math.isfinite(d.wall_hi) and p >= d.wall_hi - tol:
        return 1
    if math.isfinite(d.wall_lo) and p <= d.wall_lo + tol:
        return -1
    return 0


def _stretch_sign(f: F, k: float, dur: float) -> tuple[int, float | None]:
    """Sign of ``f`` on its first stretch after TAU_MIN, and where it ends (within
    ``dur``); a sign change closer to the start than TAU_MIN is float noise."""
    lo = min(TAU_MIN, dur / 2.0)
    found = xp.roots5(f, k, lo, dur)
    if found:
        return _sign(xp.value(f, k, (lo + found[0]) / 2.0)), found[0]
    end = dur if dur != math.inf else lo + 2.0
    return _sign(xp.value(f, k, (lo + end) / 2.0)), None


def _beyond(name: str, f: F, dur: float, limit: float) -> Exits:
    """Exits for ``|f| > limit`` within ``dur``, only when a bound says it may happen."""
    if xp.abs_bound(f, dur) <= limit:
        return []
    return [(name, [xp.plus(f, -limit)]), (name, [xp.plus(xp.scale(f, -1.0), -limit)])]


def _rest_piece(t: float, p: float, cmd: F, d: Drive) -> Piece:
    """Safety net after MAX_PIECES: hold still (logged by the axis); a free motor
    makes no torque."""
    torque = xp.const(d.a_load) if d.enabled else xp.ZERO
    return Piece(t, math.inf, STALL, xp.const(p), cmd, torque, 0.0)
