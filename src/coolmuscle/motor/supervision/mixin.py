"""What a motor does around its motion: torque limit, alarms, push, origin search, travel
limits, temperature, faults and the machine it drives.

:class:`Supervision` is a mixin of :class:`~coolmuscle.motor.motor.Motor`; it keeps
motor.py small.  It owns the wiring between the motor and :mod:`.alarms`, :mod:`.push`,
:mod:`.origin`, :mod:`.limits`, :mod:`.thermal`, :mod:`.faults` and :mod:`.sensors`, and
the public actions the executors and input functions call:

* ``push_to(target, limits, via=())`` (2.2.2 "Q"/"Z", 4.1.4),
* ``origin_search()`` (``|``, input function 7, 5.3),
* ``limit_sensor(direction, on)`` (input functions 6/9),
* ``set_torque_limit(percent)`` (``M``: 2.1.1 "Soon after setting M data..."),
* ``motion_done()`` / ``add_motion_listener(callback)``: whether the last motion (move,
  push, origin search) is complete, and a callback when one completes,
* ``inject_fault(fault, **params)`` (docs/machine-file.md).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Callable, Sequence

from .alarms import alarm_watchers
from ..motion.dynamics import Drive
from .faults import Faults
from .limits import TravelLimits
from .origin import STOPPER, OriginSearch, auto_start
from ..motion.planner import Limits
from .push import Push
from .sensors import Geometry
from ..status import ALARM_BITS, Ux
from .thermal import Thermal

if TYPE_CHECKING:
    from ..motor import Motor

MotionListener = Callable[[str], None]

#: K parameters whose change re-solves the motion (limits, thresholds, resolution).
_RESOLVE_ON = frozenset({37, 40, 47, 55, 56, 57, 60, 61})

#: CM2 driver temperature alarm (°C); CM1 uses K71 (Appendix A "Temperature limit").
CM2_TEMPERATURE_ALARM = 85.0


class Supervision:
    """Mixin: everything around the motion of one :class:`Motor`."""

    def _init_supervision(self: "Motor") -> None:
        """State the drive needs (before the axis exists)."""
        self.thermal = Thermal(alarm=self._temperature_alarm())
        self.thermal.reset(None, self.kernel.now)
        self.faults = Faults(self)
        self.travel = TravelLimits(self)
        self.push = Push(self)
        self.origin = OriginSearch(self)
        self.geometry = Geometry()
        self.input_driven = [False] * (self.io.input_count + 1)
        self._motion_listeners: list[MotionListener] = []

    def _attach_supervision(self: "Motor") -> None:
        """Watch the axis: alarms, push, origin search; heat before each re-solve."""
        self.axis.before_resolve.append(self.thermal.advance)
        self.plant.on_change = self.axis.refresh
        for watcher in (*alarm_watchers(self), self.push, self.origin):
            self.axis.add_watcher(watcher)

    def _temperature_alarm(self: "Motor") -> float:
        if self.firmware.name == "cm1":
            return float(self.k(71))
        return CM2_TEMPERATURE_ALARM

    # -- the drive ---------------------------------------------------------------
    def drive(self: "Motor") -> Drive:
        """Dynamics parameters now: plant, torque limit, machine, faults."""
        if self.faults.power_cable_broken:
            limit = 0.0
        elif self.push.active:
            limit = self.push.level_percent()
        else:
            limit = self.torque_limit * self.plant.peak_torque / 100.0
        ppr = self.resolution.pulses_per_rev
        extra = self.faults.extra_load_percent / 100.0 * self.plant.rated_torque
        return self.plant.drive(ppr, limit_percent_of_rated=limit, enabled=True,
                                speed_scale=self.faults.speed_scale(), extra_load_nm=extra,
                                walls=self.geometry.walls(ppr), speed_limit=self.k(40))

    def set_torque_limit(self: "Motor", percent: int) -> None:
        """``M`` (2.1.1): the torque limit, % of the maximum torque, applies at once."""
        percent = max(0, min(100, int(percent)))
        if percent != self.torque_limit:
            self.torque_limit = percent
            self.axis.refresh()

    @property
    def push_error(self: "Motor") -> bool:
        """The push error (Ux=256) is latched (4.1.4 "alarm state")."""
        return self.push.status_bits() == int(Ux.PUSH_ERROR)

    def position_error_exempt(self: "Motor") -> bool:
        """No position error overflow while pushing or searching a stopper."""
        return self.push.active or (self.origin.active and self.origin.source == STOPPER)

    def _supervision_param(self: "Motor", k: int) -> None:
        if k == 45:
            sign = -1 if self.k(45) % 10 >= 2 else 1
            if sign != self.axis.sign:
                self.axis.sign = sign
                self.axis.refresh()
        if k == 71 and self.firmware.name == "cm1":
            self.thermal.alarm = float(self.k(71))
        if k in _RESOLVE_ON or k == 71:
            self.axis.refresh()

    # -- temperature and machine ------------------------------------------------------
    @property
    def temperature(self: "Motor") -> int:
        """?71 Temp (°C)."""
        return round(self.thermal.temperature_at(self.axis.motion, self.kernel.now))

    def set_temperature(self: "Motor", celsius: float) -> None:
        """The case is at ``celsius`` now (fault injection, machine file)."""
        self.thermal.advance(self.axis.motion, self.kernel.now)
        self.thermal.reset(celsius, self.kernel.now)
        if celsius > self.thermal.alarm:
            self.raise_alarm(int(Ux.TEMPERATURE))
        self.axis.refresh()

    def z_position(self: "Motor") -> float:
        """Raw position of the Z phase / encoder phase 0 (machine file, default 0)."""
        return self.geometry.z_raw(self.resolution.pulses_per_rev)

    # -- actions -----------------------------------------------------------------
    def push_to(self: "Motor", target: float, limits: Limits | None,
                via: Sequence[tuple[float, Limits | None]] = ()) -> None:
        """Push motion toward user position ``target`` (4.1.4), merging through ``via``.

        Zero speed data (no limits) means no motion (docs/fidelity.md "Motion")."""
        if not self.can_move() or limits is None or any(lim is None for _, lim in via):
            return
        points = [(self.travel.clamp(t), lim) for t, lim in (*via, (target, limits))]
        if self.travel.blocked(self.axis.to_raw(points[-1][0]) - self.axis.raw_command()):
            return
        self.abandon_motion()
        self._last_limits = limits
        self.push.start(points[-1][0], points[-1][1], points[:-1])

    def origin_search(self: "Motor") -> None:
        """``|`` / input function 7: origin search (5.3)."""
        if not self.can_move():
            return
        self.abandon_motion()
        self.origin.start()

    def limit_sensor(self: "Motor", direction: int, on: bool) -> None:
        """A CW (+1) / CCW (-1) limit sensor changed (input functions 6, 9)."""
        self.travel.sensor(direction, on)

    @property
    def limit_sensors(self: "Motor") -> dict[int, bool]:
        """Limit sensor states: {+1: CW on, -1: CCW on} (read only)."""
        return dict(self.travel.on)

    def inject_fault(self: "Motor", fault: str, **params: object) -> None:
        """Fault injection through the device API (docs/machine-file.md "Faults")."""
        self.faults.inject(fault, **params)

    def _stop_push(self: "Motor") -> bool:
        """A stop while pushing: the shaft's position becomes the target (ch. 3 K55
        "the stopped position is recognized as the target position")."""
        if not self.push.active:
            return False
        self.abandon_motion()
        self.axis.follow(self.axis.position())
        return True

    def abandon_motion(self: "Motor") -> None:
        """A push or origin search in progress ends without completing."""
        self.push.clear()
        self.origin.cancel()

    def _allowed_target(self: "Motor", user: float) -> float | None:
        """``user`` within the software limits, or None when a limit sensor refuses."""
        user = self.travel.clamp(user)
        if self.travel.blocked(self.axis.to_raw(user) - self.axis.raw_command()):
            return None
        return user

    def _continuous_blocked(self: "Motor", s_value: int, limits: Limits) -> bool:
        """Limit sensors refuse, software limits turn the rotation into a move (2.1.1)."""
        direction = self.axis.sign * (1 if s_value > 0 else -1 if s_value < 0 else 0)
        if self.travel.blocked(direction):
            return True
        lo, hi = self.travel.soft_range()
        stop_at = hi if s_value > 0 else lo if s_value < 0 else math.nan
        if math.isfinite(stop_at):
            self.axis.move([(stop_at, limits)])
            return True
        return False

    # -- completion ----------------------------------------------------------------
    def motion_done(self: "Motor") -> bool:
        """No move, push or origin search in progress (what ``P``/``Q`` lines wait for)."""
        return not (self.axis.moving or self.push.active or self.origin.active)

    def add_motion_listener(self: "Motor", listener: MotionListener) -> Callable[[], None]:
        """Call ``listener(reason)`` whenever a motion completes; returns a remover.

        Reasons: ``in-position``, ``push-complete``, ``push-error``, ``origin-complete``,
        ``alarm``, ``free``.
        """
        self._motion_listeners.append(listener)

        def remove() -> None:
            if listener in self._motion_listeners:
                self._motion_listeners.remove(listener)
        return remove

    def notify_motion_done(self: "Motor", reason: str) -> None:
        for listener in list(self._motion_listeners):
            listener(reason)
        self.motion_settled()

    def push_finished(self: "Motor", ux: int, reason: str) -> None:
        """The push completed (40), failed (256) or ended at its target (8)."""
        if reason == "push-complete":
            self.axis.hold_here()
        else:
            self.axis.refresh()
        self.report_status()
        self.notify_motion_done(reason)
        del ux

    def _arrival(self: "Motor") -> None:
        """In position at the end of a leg: the origin search, a push or a plain move."""
        if self.origin.active:
            self.origin.arrived()
        elif self.push.active:
            self.push.arrived()
        else:
            if not self.estopped and not self.alarm:   # those were reported when they began
                self.report_status()
            self.notify_motion_done("in-position")

    def _alarm_latched(self: "Motor", bits: int) -> bool:
        """Latch alarm ``bits``; False when nothing new."""
        bits &= int(ALARM_BITS)
        if not bits or self.alarm & bits == bits:
            return False
        self.alarm |= bits
        self.abandon_motion()
        self.axis.enabled = False
        self.report_status()
        self.notify_motion_done("alarm")
        return True

    def _supervision_status(self: "Motor") -> int | None:
        """Ux from the origin search and the push, or None."""
        if self.origin.active:
            return int(Ux.RUNNING)
        bits = self.push.status_bits()
        return bits or None

    # -- inputs ------------------------------------------------------------------------
    def _input_driven(self: "Motor", number: int, on: bool) -> bool:
        """Record the driven level; returns the level the input shows (faults)."""
        if 1 <= number < len(self.input_driven):
            self.input_driven[number] = bool(on)
        return self.faults.input_level(number, bool(on))

    def _input_changed(self: "Motor", number: int) -> None:
        """Signal of input ``number`` changed: the origin search watches its sensor (the
        limit sensors come through the input functions, :mod:`.inputs`)."""
        self.origin.on_input(number)

    def refresh_inputs(self: "Motor") -> None:
        """Re-apply the faults to every driven input level."""
        for number in range(1, self.io.input_count + 1):
            self.set_input_level(number, self.input_driven[number])

    def _power_on_search(self: "Motor") -> None:
        """Power-up: saved K45 / K71 take effect; odd K46 starts an origin search."""
        self._supervision_param(45)
        self.thermal.alarm = self._temperature_alarm()
        if auto_start(self.k(46)) and self.axis.enabled:
            self.kernel.call_soon(self.origin_search, name="power-on origin search")
