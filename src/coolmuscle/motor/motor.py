"""One Cool Muscle motor: parameters, data, I/O, axis, status and the actions CML commands call.

The statement executors (:mod:`.direct`, later program and ladder banks) call the
action methods here; nothing else changes motor state.  Every report goes out through
the :class:`MotorBus` (the chain), which puts it on the host line and the event
stream.  Spec: cml-users-guide.txt 2.1.2 (execution commands), ch. 3 (K parameters),
6.6 (status), K23 (reports).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Final

from ..cml import ast
from ..errors import MotorError, OutOfRangeError
from ..sim.kernel import Kernel, nearest
from ..sim.memo import Key, Memo
from .context import Context
from .core import MotorBus
from .motion.axis import Axis, Servo
from .motion.dynamics import Drive, Motion, MotionMemos
from .motion.planner import ESTOP_DECEL, Limits, limits_from_data
from .motion.plant import DEFAULT_KP, STEPPER_KP, Plant
from .motion.profile import Profile
from .motion.trajectory import Timeline
from .programs.evaluate import pack_string
from .signals.analog import AnalogInput, AnalogSource
from .signals.analog_control import AnalogControl
from .signals.analog_output import output_volts, volts_to_register
from .signals.encoder import ExternalEncoder, Gearing
from .signals.io import DigitalIO
from .signals.manual import ManualMotion
from .signals.pulses import RotationPulses
from .state import units
from .state.firmware import Firmware
from .state.memory import Memory, VNumber, VState, VString
from .state.output_functions import (
    OUT_ALARM,
    OUT_IN_POSITION,
    OUT_MERGE_PULSE,
    OUT_MOTOR_FREE,
    OUT_ORIGIN_DONE,
    OUT_PUSH,
    OUT_PUSH_AT_LEVEL,
    OUT_ROTATION_PULSE,
)
from .state.param_table import ParamTable
from .status import Report, Ux, io_word_hex, status_line
from .supervision.origin import STOPPER
from .supervision.supervisor import Supervisor

if TYPE_CHECKING:
    from .core import MotorCore
    from .programs.coordinated import PairMotion

log = logging.getLogger(__name__)

_IN_POSITION: Final = int(Ux.IN_POSITION)


#: The K20 table (ch. 3 K20) as the confirmation message writes the rate.
_K20_KBPS = {0: "38.4", 1: "9.6", 2: "19.2", 3: "57.6", 4: "115.2", 5: "230.4"}


class Motor(Servo):
    """A virtual COOL MUSCLE: the only place motor behaviour lives."""

    def __init__(self, motor_id: int, kernel: Kernel, firmware: Firmware, bus: MotorBus,
                 memos: MotionMemos | None = None) -> None:
        """``memos``: the plans and solved motions of the chain (shared by its motors);
        without, the motor keeps its own."""
        self.id = motor_id
        self.kernel = kernel
        self.firmware = firmware
        self.bus = bus
        self.params = ParamTable(firmware)
        #: limits() by (S, A, decel data, params.version): K37/K44/K51/K69/K40 as then
        self._limits_memo: Memo[Key, Limits] = Memo(256)
        self._resolution = units.resolution(self.params.get(37))
        self._resolution_version = self.params.version
        self.memory = Memory(firmware, k37=self.k(37))
        self.params.on_change(self._param_changed)
        self.io = DigitalIO(firmware.inputs, firmware.outputs, self.params,
                            self._output_function_signal, firmware.output_functions,
                            one_logic=firmware.one_logic,
                            inverting_logic=firmware.inverting_logic)
        self.plant = Plant(kp=DEFAULT_KP if firmware.is_servo else STEPPER_KP)
        self.alarm = 0
        self.voltage = 240
        #: torque limit, alarms, push, origin search, travel limits, temperature, faults;
        #: its parts are the motor's too (the machine file, the device API, tests)
        self.supervision = sup = Supervisor(self)
        self.thermal, self.faults, self.travel = sup.thermal, sup.faults, sup.travel
        self.push, self.origin, self.geometry = sup.push, sup.origin, sup.geometry
        self.axis = Axis(kernel, self, memos=memos)
        self.axis.half_range = units.counter_half_range(self._resolution.pulses_per_rev)
        sup.attach()
        self.estopped = False
        self.origin_done = False
        self.merge_pulse_until = 0
        self._last_limits: Limits | None = None
        # -- signals (5.1, 5.2, 5.4, 5.5; K24, K35, K38-K41, K71-K77): own modules
        self.timeline = Timeline(self.axis)
        self.pulses = RotationPulses(self, self.timeline)
        self.analog_input = AnalogInput(lambda: kernel.now)
        self.analog_control = AnalogControl(self, self.analog_input)
        self.encoder = ExternalEncoder(self, self.timeline)
        self.manual = ManualMotion(self)
        # -- banks, ladder, input functions (2.2.2, 2.2.3, K27-K32).  Imported here: the executors
        # use .direct, which imports this module.
        from .programs.banks import BankStore
        from .programs.ladder import LadderRunner
        from .programs.program import ProgramExecutor
        from .signals.inputs import InputFunctions
        self.banks = BankStore(firmware)
        self.program = ProgramExecutor(self)
        self.ladder = LadderRunner(self)
        self.logic_motion = LadderRunner(self, motion=True)
        self.inputs = InputFunctions(self)
        self._go_target: int | None = None     # P0 of a running "^" (S0 stays live)
        self._go_speed: int | None = None
        self._go_data: tuple[int, int, int] | None = None
        self._state_readers: dict[str, Callable[[], int]] | None = None
        # -- interpolation (4.4, :mod:`.coordinated`): the path this axis follows and
        # which of R0 / N0 direct-mode "@" uses (the one written last)
        self.path: PairMotion | None = None
        self.direct_interp_kind = "R"
        #: a K20 value waiting for the host's Y/N (ch. 3 K23 16)
        self.pending_baud: int | None = None

    # -- parameters and units ----------------------------------------------
    @property
    def resolution(self) -> units.Resolution:
        """K37's resolution (ch. 3 K37 table), kept while no K value changes."""
        if self._resolution_version != self.params.version:
            self._resolution = units.resolution(self.k(37))
            self._resolution_version = self.params.version
        return self._resolution

    def max_position(self) -> int:
        """Maximum |P| for the current K37 (ch. 3 K37 table)."""
        return self.resolution.max_position

    def _param_changed(self, k: int, old: int, new: int) -> None:
        del old
        if k == 37:
            self.memory.set_k37(new)
            self.axis.half_range = units.counter_half_range(self.resolution.pulses_per_rev)
        self.supervision.param_changed(k)

    def k(self, number: object) -> int:
        """The current value of K parameter ``number`` (ch. 3); looked up as the table
        looks it up (:meth:`ParamTable.get`: 37.0 finds K37 there too)."""
        return self.params.get(number)

    def reports(self, flag: Report) -> bool:
        """Whether K23 includes ``flag``."""
        return bool(self.k(23) & int(flag))     # int & int: no IntFlag made, no enum property

    # -- status ---------------------------------------------------------------
    @property
    def status(self) -> int:
        """Ux (6.6 ?99)."""
        if self.alarm:
            return self.alarm
        if self.estopped:
            return int(Ux.EMERGENCY_STOP)
        if not self.axis.enabled:
            return int(Ux.MOTOR_FREE)
        special = self.supervision.status()
        if special is not None:
            return special
        return 0 if self.axis.moving else _IN_POSITION

    def position(self) -> int:
        """Px (?96), whole pulses."""
        return nearest(self.axis.position())

    def cyclic_values(self, now: int) -> tuple[int, int, int, float, int, int, int, bool,
                                                bool, bool]:
        """What a fieldbus cycle reads of the motor at ``now``, in the order of the device
        API's ``CyclicState`` (every axis of an EtherCAT segment every millisecond)."""
        axis, io = self.axis, self.io
        return (self.id, now, self.position(), axis.velocity(), self.status, io.input_word(),
                io.output_word(), axis.enabled, bool(self.origin.active),
                bool(self.origin_done))

    def speed_units(self) -> int:
        """Sx (?97): actual speed in K37 speed units, to the nearest unit."""
        return nearest(self.axis.velocity() / self.resolution.speed_unit_pps)

    def torque(self) -> int:
        """Ix (?98): % of rated torque."""
        return nearest(self.torque_exact())

    def torque_exact(self) -> float:
        """Ix before it is rounded to a whole %: what ``?98`` reads (the twin's fit
        compares these, not the rounded replies: coolmuscle.tools.twin)."""
        if not self.axis.enabled:
            return 0.0
        commanded = self.analog_control.torque_percent()
        if commanded is not None:
            return float(commanded)
        load = self.analog_control.load_percent()       # a torque-sensor load (5.5)
        return load + self.axis.torque_percent()

    # -- reports --------------------------------------------------------------
    def say(self, ctx: Context | None, text: str, kind: str = "reply",
            value: int | None = None) -> None:
        """A reply or message: to the context's collector and the bus."""
        origin = ctx.origin if ctx else "motor"
        if ctx is not None and ctx.replies is not None:
            ctx.replies.append(text)
        self.bus.emit(self.id, kind, text, value=value, origin=origin)

    def report_error(self, ctx: Context | None, error: MotorError) -> None:
        """``errorNN.n: ...`` when K23 includes 16, otherwise silence (ch. 3 K23)."""
        if self.reports(Report.MESSAGES):
            self.say(ctx, error.motor_line(self.id), kind="message")

    def report_status(self) -> None:
        """``Ux.n=..`` event when K23 includes 1 (in-position and alarms)."""
        if self.reports(Report.IN_POSITION_AND_ALARM):
            ux = self.status
            kind = "alarm" if self.alarm else "status"
            # positional: a call through the bus protocol with keywords is parsed slowly
            self.bus.emit(self.id, kind, status_line(self.id, ux), ux)

    def report_outputs(self) -> None:
        """``OUT.n=..`` event when K23 includes 4 (general outputs only)."""
        if self.reports(Report.OUTPUT_CHANGE):
            word = self.io.output_word()
            self.bus.emit(self.id, "output",
                          f"OUT.{self.id}={io_word_hex(word, self.io.output_count)}",
                          value=word)

    def report_inputs(self) -> None:
        """``IN.n=..`` event when K23 includes 2."""
        if self.reports(Report.INPUT_CHANGE):
            word = self.io.input_word()
            self.bus.emit(self.id, "input",
                          f"IN.{self.id}={io_word_hex(word, self.io.input_count)}",
                          value=word)

    # -- motion ---------------------------------------------------------------
    def can_move(self) -> bool:
        return self.axis.enabled and not self.alarm and not self.estopped

    def limits(self, s_value: int, a_value: int, decel_a: int | None = None) -> Limits | None:
        """Motion limits from S/A data and K37, K44, K51, K69 (ch. 3).

        ``None`` when the speed, acceleration or deceleration data is 0: such a motion
        does not move (docs/fidelity.md "Motion").
        """
        if s_value == 0 or a_value == 0 or decel_a == 0:
            return None
        key: Key = (s_value, a_value, decel_a, self.params.version)
        found = self._limits_memo.get(key)
        if found is not None:                   # the same data under the same K values
            return found
        lim = limits_from_data(s_value, a_value, k37=self.k(37), k44=self.k(44),
                               k51=self.k(51), k69=self.k(69), decel_a_value=decel_a)
        top = self.max_speed_pps()
        if lim.speed > top:            # ch. 3 K40: S above the maximum is limited to it
            lim = replace(lim, speed=top, creep=min(lim.creep, top))
        return self._limits_memo.put(key, lim)

    def max_speed_pps(self) -> float:
        """K40 (the motor's maximum speed, min⁻¹) in pulses/s of the current K37:
        S value = speed x resolution / speed unit / 60 (ch. 3 K40)."""
        return units.rpm_to_pps(self.k(40), self.k(37))

    def move_to(self, waypoints: Sequence[tuple[float, Limits | None]],
                delay_ns: int = 0) -> None:
        """Start (or re-plan) a move through user-coordinate waypoints.

        A waypoint without limits (zero speed) means no motion at all.  ``delay_ns``: the
        command is still on its way down the chain (ch. 3 K65), it starts that much later.
        """
        self._go_target = None
        if not self.can_move() or not waypoints:
            return
        points: list[tuple[float, Limits]] = []
        for t, lim in waypoints:
            if lim is None:
                return
            points.append((self.travel.clamp(t), lim))
        if self.supervision.allowed_target(points[-1][0]) is None:
            return
        self.supervision.abandon_motion()
        self._last_limits = points[-1][1]
        self.axis.move(points, start_ns=self.kernel.now + delay_ns if delay_ns else None)

    def path_end_allowed(self, user_end: float) -> bool:
        """Whether an interpolation path may take this motor to ``user_end``: it can move,
        the end is within the software limits (K58, K59) and not toward an active limit
        sensor (which reports its error, as for a move)."""
        return self.can_move() and self.supervision.allowed_target(user_end) == user_end

    def run_path(self, path: PairMotion, profile: Profile, limits: Limits) -> bool:
        """Follow one axis of an interpolation path (4.4); False if the motor cannot move."""
        self._go_target = None
        if not self.can_move():
            return False
        self.supervision.abandon_motion()
        self._last_limits = limits
        self.axis.run_profile(profile)
        self.path = path
        return True

    def run_continuous(self, s_value: int, limits: Limits | None) -> None:
        """Continuous rotation, P=1000000000 (2.1.1): direction from the sign of S.

        Zero speed (no limits) stops a rotation in progress.
        """
        self._go_target = None
        if not self.can_move():
            return
        if limits is None:
            if self.axis.moving:
                self.stop()
            return
        self.supervision.abandon_motion()
        self._last_limits = limits
        if self.supervision.continuous_blocked(s_value, limits):
            return
        pps = s_value * self.resolution.speed_unit_pps
        self.axis.run(math.copysign(min(abs(pps), limits.speed), pps), limits)   # K40

    def go(self) -> None:
        """``^``: execute the direct data P0, S0, A0, M0 (2.1.2).

        S0 stays live while the motion runs: writing S0 changes its speed, S0 = 0
        halts it short of P0 until S0 is set again (2.2.3 operation example, where a
        ladder bank switches S.1 during a ``^`` move; cm-banks-rt3.txt 7.1-7.3).
        """
        p0 = int(self.memory.get("P", 0))
        self.supervision.torque_limit = int(self.memory.get("M", 0))
        same = (p0, int(self.memory.get("S", 0)), int(self.memory.get("A", 0)))
        if self._go_target is not None and self.axis.moving and same == self._go_data:
            return   # that very motion is running already (RT3 7.2 sends ^ every scan)
        self._run_go(p0)

    def _run_go(self, p0: int) -> None:
        s0 = int(self.memory.get("S", 0))
        a0 = int(self.memory.get("A", 0))
        if s0 == 0 or a0 == 0:
            if self.axis.moving:
                self.stop()
        else:
            lim = self.limits(s0, a0)
            assert lim is not None                # S0 and A0 are not 0
            if self.encoder.handles_go(p0, s0, lim) or self.analog_control.handles_go(p0, lim):
                pass                          # index / feedback (K71), torque feedback (K38)
            elif p0 == units.CONTINUOUS:
                self.run_continuous(s0, lim)
            else:
                self.move_to([(float(p0), lim)])
        self._go_target, self._go_speed, self._go_data = p0, s0, (p0, s0, a0)

    def direct_speed_changed(self) -> None:
        """S0 was written: a running ``^`` motion takes the new speed (see :meth:`go`)."""
        target = self._go_target
        if target is None or int(self.memory.get("S", 0)) == self._go_speed:
            return
        if self.can_move():
            self._run_go(target)

    def go_origin(self) -> None:
        """``|1``: move to position 0 with K42 speed and K43 acceleration (2.1.2)."""
        self.move_to([(0.0, self.limits(self.k(42), self.k(43)))])

    def set_origin(self) -> None:
        """``|2``: the current position becomes 0, no motion (2.1.2)."""
        self.axis.set_user_position(0.0)

    def stop(self) -> None:
        """``]``/``}``-style decelerating stop at the motion's deceleration; an
        interpolating pair decelerates along its path (docs/fidelity.md "Daisy chain")."""
        self._go_target = None
        if self.path is not None and self.path.owns(self):
            self.path.stop(self.kernel.now)
            return
        lim = self._last_limits or self.limits(self.k(49), self.k(43))
        assert lim is not None                    # K43 and K49 are at least 1 (ch. 3)
        if self.supervision.stop_push():
            return
        self.supervision.abandon_motion()
        self.axis.stop(lim.decel, lim.scurve, creep=lim.creep, speed=lim.speed)

    def emergency_stop(self) -> None:
        """``*``: stop at maximum deceleration; Ux=512 until ``*1`` (2.1.2)."""
        self._go_target = None
        if not self.supervision.stop_push():
            self.supervision.abandon_motion()
            self.axis.stop(ESTOP_DECEL)
        if not self.estopped:
            self.estopped = True
            self.report_status()

    def emergency_release(self, *, force: bool = False) -> None:
        """``*1``: cancel the emergency stop and enable the motor (2.1.2).

        Not while an input with function 7 holds it (ch. 3 K27 "can not be canceled
        by CML command"); the input itself releases with ``force``.
        """
        if self.estopped and (force or not self.inputs.estop_held()):
            self.estopped = False
            self.enable()

    def enable(self) -> None:
        """``(``: servo on; also clears a latched alarm (CM1 manual 3.2.3 ControlWord 3)."""
        self.alarm = 0
        self.supervision.abandon_motion()
        self.axis.hold_here()
        self.axis.enabled = True
        self.motion_settled()

    def free(self) -> None:
        """``)``: motor free (servo off); the shaft coasts to rest where it is."""
        self._go_target = None
        self.supervision.abandon_motion()
        was_moving = not self.motion_done()
        self.axis.enabled = False
        if was_moving:
            self.supervision.notify_motion_done("free")
        self.motion_settled()

    def reset_alarm(self) -> None:
        """Alarm reset (input function 1, K28–K32): clear the alarm, servo on again."""
        if self.alarm or self.supervision.push_error:
            self.enable()

    def jog(self, direction: int) -> None:
        """Manual jog (5.1): K50 pulses CW (+1) or CCW (-1); see :mod:`.manual`."""
        self.manual.jog(direction)

    def feed(self, direction: int) -> None:
        """Manual feed on (5.1): rotate CW (+1) / CCW (-1) at K49 with K43."""
        self.manual.feed(direction)

    def feed_stop(self) -> None:
        """Manual feed off: decelerate; a blocked feed may start again (5.1)."""
        self.manual.feed_stop()

    def raise_alarm(self, bits: int) -> None:
        """An alarm: report it, go free, raise the K34 alarm output (ch. 3 K56, K57)."""
        if self.supervision.alarm_latched(bits):
            self.program.alarm()
            self.motion_settled()

    def capture(self, index: int) -> None:
        """``#x``: P[x] := current position (2.1.2)."""
        self.memory.set("P", index, self.position())

    # -- supervision: push, origin search, limits, faults (supervision/supervisor.py) ----
    def push_to(self, target: float, limits: Limits | None,
                via: Sequence[tuple[float, Limits | None]] = ()) -> None:
        """Push motion toward user position ``target`` (4.1.4), merging through ``via``.

        Zero speed data (no limits) means no motion (docs/fidelity.md "Motion")."""
        if self.supervision.push_to(target, limits, via):
            self._last_limits = limits

    def set_torque_limit(self, percent: int) -> None:
        """``M`` (2.1.1): the torque limit, % of the maximum torque, applies at once."""
        self.supervision.set_torque_limit(percent)

    def select_torque_limit(self, percent: int) -> None:
        """A bank line's ``M#``: the torque limit of the motions that follow (the running
        one keeps its solution)."""
        self.supervision.torque_limit = percent

    def drive(self) -> Drive:
        """Dynamics parameters now: plant, torque limit, machine, faults."""
        return self.supervision.drive()

    def origin_search(self) -> None:
        """``|`` / input function 7: origin search (5.3)."""
        self.supervision.origin_search()

    def limit_sensor(self, direction: int, on: bool) -> None:
        """A CW (+1) / CCW (-1) limit sensor changed (input functions 6, 9)."""
        self.travel.sensor(direction, on)

    @property
    def limit_sensors(self) -> dict[int, bool]:
        """Limit sensor states: {+1: CW on, -1: CCW on} (read only)."""
        return dict(self.travel.on)

    def inject_fault(self, fault: str, **params: object) -> None:
        """Fault injection through the device API (docs/machine-file.md "Faults")."""
        self.faults.inject(fault, **params)

    def position_error_exempt(self) -> bool:
        """No position error overflow while pushing or searching a stopper."""
        return self.push.active or (self.origin.active and self.origin.source == STOPPER)

    def abandon_motion(self) -> None:
        """A push or origin search in progress ends without completing."""
        self.supervision.abandon_motion()

    def motion_done(self) -> bool:
        """No move, push or origin search in progress (what ``P``/``Q`` lines wait for)."""
        return not (self.axis.moving or self.push.active or self.origin.active)

    def add_motion_listener(self, listener: Callable[[str], None]) -> Callable[[], None]:
        """Call ``listener(reason)`` whenever a motion completes; returns a remover.

        Reasons: ``in-position``, ``push-complete``, ``push-error``, ``origin-complete``,
        ``alarm``, ``free``.
        """
        return self.supervision.add_motion_listener(listener)

    def notify_motion_done(self, reason: str) -> None:
        """A motion completed: tell the listeners, let waiting bank lines look again."""
        self.supervision.notify_motion_done(reason)

    def push_finished(self, ux: int, reason: str) -> None:
        """The push completed (40), failed (256) or ended at its target (8)."""
        del ux
        self.supervision.push_finished(reason)

    def refresh_inputs(self) -> None:
        """Re-apply the faults to every driven input level."""
        self.supervision.refresh_inputs()

    # -- temperature and machine ------------------------------------------------------
    @property
    def temperature(self) -> int:
        """?71 Temp (°C)."""
        return nearest(self.thermal.temperature_at(self.axis.motion, self.kernel.now))

    def set_temperature(self, celsius: float) -> None:
        """The case is at ``celsius`` now (fault injection, machine file)."""
        self.supervision.set_temperature(celsius)

    def z_position(self) -> float:
        """Raw position of the Z phase / encoder phase 0 (machine file, default 0)."""
        return self.geometry.z_raw(self.resolution.pulses_per_rev)

    def in_position_window(self) -> int:
        """K55 (ch. 3), pulses: what the axis asks at every motion."""
        return self.params.get(55)

    def motion_ends(self, motion: Motion, now: int) -> None:
        """The axis replaces ``motion`` at ``now``: the heat it made until then."""
        self.thermal.advance(motion, now)

    def in_position(self) -> None:
        """The axis came within K55 of its target (Ux=8): the leg's end."""
        if self._go_speed:            # a "^" reached P0 (not halted by S0 = 0): done
            self._go_target = None
        self.supervision.arrival()
        self.motion_settled()

    # -- motion completion (the bank executors wait on these) ------------------------
    def motion_settled(self) -> None:
        """A motion ended: let waiting bank lines look again (no polling)."""
        self.bus.poke(self.id)

    def passing_point(self, index: int) -> None:
        """K34=6: the output is on for K73 ms from each passing point; a point within
        the pulse of the previous one lengthens it (ch. 3 K73)."""
        del index
        self.merge_pulse_until = self.kernel.now + self.k(73) * 1_000_000
        # an event where the K34=6 pulse ends, so traces and waits see the output fall
        self.kernel.schedule_at(self.merge_pulse_until, self.bus.poke, name="merge-pulse-end")

    # -- outputs ----------------------------------------------------------------
    def _output_function_signal(self, function: int, number: int) -> bool:
        if function == OUT_IN_POSITION:
            return self.status & _IN_POSITION != 0          # int & int: no enum
        if function == OUT_ALARM:
            return self.alarm != 0 or self.supervision.push_error
        if function == OUT_ORIGIN_DONE:
            return self.origin_done and self.status == _IN_POSITION
        if function == OUT_MERGE_PULSE:
            return self.kernel.now < self.merge_pulse_until
        if function == OUT_ROTATION_PULSE:
            return self.pulses.signal(number)
        if function == OUT_MOTOR_FREE:
            return not self.axis.enabled
        if function == OUT_PUSH:
            return self.push.active
        if function == OUT_PUSH_AT_LEVEL:
            return self.push.at_level
        return False

    def set_output(self, number: int, on: bool) -> None:
        """``O#``/``F#`` (2.1.2); only outputs whose K34 function follows that command
        change (CM2 digit 3; CM1 0, 3, 4)."""
        if self.io.set_general(number, on):
            self.report_outputs()

    def set_input_level(self, number: int, on: bool) -> None:
        """Drive an input's electrical level (device API, machine file); the input
        functions of K27-K32 follow (:mod:`.inputs`), faults may hold it (:mod:`.faults`)."""
        if self.io.set_level(number, self.supervision.input_level(number, on)):
            self.report_inputs()
            self.origin.on_input(number)    # the origin search watches its sensor
            self.inputs.signal_changed(number)
        self.bus.poke()

    # -- V registers and live states --------------------------------------------
    def state_value(self, name: str) -> int:
        """A bound V state read live (2.2.1 "V"; cm-banks-rt3.txt 1.3)."""
        readers = self._state_readers
        if readers is None:
            readers = self._state_readers = self._make_state_readers()
        reader = readers.get(name)
        return int(reader()) if reader else 0

    def _make_state_readers(self) -> dict[str, Callable[[], int]]:
        return {
            "Px": self.position, "Sx": self.speed_units, "Ix": self.torque,
            "Ux": lambda: self.status, "Pe": lambda: round(self.axis.position_error()),
            "ADIN": lambda: self.analog, "PT": lambda: round(self.axis.target())
            if abs(self.axis.target()) != float("inf") else units.CONTINUOUS,
            "ST": lambda: int(self.memory.get("S", 0)), "CT": lambda: self.encoder_count,
            "Dx": lambda: round(self.axis.target()) if abs(self.axis.target()) != float("inf")
            else 0,
            "Fx": lambda: round(self.encoder.frequency()), "Cx": lambda: self.encoder_count,
        }

    def v_numeric(self, value: VNumber | VString | VState) -> int:
        if isinstance(value, VState):
            return self.state_value(value.name)
        if isinstance(value, VString):
            return pack_string(value.text)
        return int(value.value)

    def register_number(self, reg: ast.Reg) -> int:
        """Numeric value of a register of this motor."""
        if reg.kind == "K":
            return self.k(reg.number)
        if reg.kind == "V":
            return self.v_numeric(self.memory.get("V", reg.number))
        return self.memory.number(reg.kind, reg.number)

    def write_register(self, kind: str, index: int, value: int | str | VState | VString) -> None:
        """Store data; raises OutOfRangeError / IndexError."""
        if kind == "K":
            if not isinstance(value, int):
                raise OutOfRangeError()
            self.params.set(index, value)
            return
        self.memory.set(kind, index, value)
        if kind == "M" and index == 0:
            self.set_torque_limit(int(self.memory.get("M", 0)))
        if kind == "S" and index == 0:
            self.direct_speed_changed()
        elif kind in ("N", "R") and index == 0:
            self.direct_interp_kind = kind     # direct "@" draws by this one (4.4)

    def propose_baud(self, ctx: Context | None, value: int) -> None:
        """``K20.n=X`` with K23 including 16: the confirmation message of the K23 table,
        "Change Baud Rate ?? XXX kbps (Y/N)"; K20 changes only when ``Y`` answers it
        (:meth:`answer_baud`).  An out-of-range value is error00 and asks nothing."""
        if not isinstance(value, int):
            raise OutOfRangeError()
        self.params.check(20, value)
        self.pending_baud = value
        kbps = _K20_KBPS.get(value, "38.4")
        self.say(ctx, f"Change Baud Rate ?? {kbps} kbps (Y/N)", kind="message")

    def answer_baud(self, yes: bool) -> None:
        """The host answered the K20 prompt: ``Y`` applies the new rate, ``N`` keeps the
        old one (docs/fidelity.md "Fidelity decisions: K37 40..70, K20 prompts, ...")."""
        value, self.pending_baud = self.pending_baud, None
        if yes and value is not None:
            self.params.set(20, value)

    def write_state(self, name: str, value: int) -> None:
        """Write through a V bound to a writable state (cm-banks-rt3.txt 1.3, 3.6).

        ``Dx`` sets the target position the servo follows at once (logic motion
        banks); ``St`` sets the target speed S0 and re-runs continuous rotation.
        """
        if name == "Dx":
            self.follow(float(value))
        elif name == "ST":
            self.memory.set("S", 0, value)
            if self.axis.moving and self.axis.profile.end_ns is None:
                self.go()

    def follow(self, target: float, period_ns: int = 0) -> None:
        """Jump the commanded position to ``target``; the servo follows (csp, Dx).  A
        stepper (CM1) in a stream of one target each ``period_ns`` ramps to it over
        the period (:meth:`.motion.axis.Axis.follow`)."""
        if self.can_move():
            self.axis.follow(self.travel.clamp(target), period_ns)

    def set_output_word(self, word: int) -> None:
        """``O.n=X``: set every general-use output from the bits of ``word``."""
        changed = False
        for number in range(1, self.io.output_count + 1):
            changed |= self.io.set_general(number, bool(word >> (number - 1) & 1))
        if changed:
            self.report_outputs()

    def direct_move(self, stmt: ast.Move) -> None:
        """``Y#``/``Q#``/``Z#`` given on the host line: move (or push) to P#."""
        target = float(self.memory.get("P", stmt.index or 0))
        if stmt.modifier is not None:
            target = self.position() + (target if stmt.modifier == "+" else -target)
        lim = self._last_limits or self.limits(int(self.memory.get("S", 0)),
                                               int(self.memory.get("A", 0)))
        if stmt.kind == "Y":
            self.move_to([(target, lim)])
        else:
            self.push_to(target, lim)

    # -- saving and power ---------------------------------------------------------
    def to_snapshot(self) -> dict[str, object]:
        """What ``$`` stores: parameters, data and banks (2.1.2 "$")."""
        return {"params": self.params.values(), "memory": self.memory.to_dict(),
                "banks": self.banks.to_dict()}

    def load_snapshot(self, saved: dict[str, object]) -> None:
        """Restore what was saved (power-up).  Data that no longer fits is skipped."""
        params = saved.get("params")
        if isinstance(params, dict):
            rejected = self.params.restore({int(k): int(v) for k, v in params.items()})
            if rejected:
                log.warning("motor %d: saved K%s not accepted", self.id, rejected)
        memory = saved.get("memory")
        if isinstance(memory, dict):
            try:
                self.memory = Memory.from_dict(self.firmware, memory, k37=self.k(37))
            except ValueError as exc:
                log.warning("motor %d: saved data skipped: %s", self.id, exc)
        self.memory.set_k37(self.k(37))
        banks = saved.get("banks")
        if isinstance(banks, dict):
            self.banks.load_dict(banks)

    def power_on(self) -> None:
        """Power-up: servo on or motor free per K68 (ch. 3 K68); input levels; the
        K62 (RT3: K85) ladder bank starts; power-up origin search (K46); analog control
        starts (K38)."""
        if self.k(68) == 0 and self.firmware.name != "cm1":   # CM1 K68: S-curve function
            self.free()
        self.inputs.power_up()
        self.ladder.power_up()
        self.supervision.power_on()
        self.analog_control.activate()

    # -- analog input / output and the external encoder (own modules) -------------
    @property
    def analog(self) -> int:
        """The analog input, 0..1023 (?74 ``ADI0``, V state ``ADIN``)."""
        return self.analog_input.counts()

    @analog.setter
    def analog(self, counts: int) -> None:
        self.analog_input.set_counts(counts)

    def set_analog_source(self, source: AnalogSource) -> None:
        """Drive the analog input from ``source`` from now on (machine file, tests)."""
        source.bind(self)
        self.analog_input.set_source(source)

    @property
    def analog_config(self) -> AnalogSource:
        """The analog input's source; setting it (machine file ``[axis.analog]``) drives
        the input from now on (docs/machine-file.md)."""
        return self.analog_input.source

    @analog_config.setter
    def analog_config(self, source: AnalogSource) -> None:
        self.set_analog_source(source)

    @property
    def encoder_config(self) -> Gearing:
        """The external encoder's gearing (machine file ``[axis.encoder]``)."""
        return self.encoder.gearing

    @encoder_config.setter
    def encoder_config(self, gearing: Gearing) -> None:
        self.encoder.set_gearing(gearing)

    @property
    def encoder_count(self) -> int:
        """The external encoder count (?76 ``Ecnt``, V states ``CT``/``Ecnt``, 5.4)."""
        return self.encoder.count()

    def analog_output_volts(self) -> float:
        """The analog output now (ch. 3 K35), volts.  Only the quantity K35 selects is
        read (a snapshot asks for it every cycle)."""
        k35, axis = self.k(35), self.axis
        kind = k35 - k35 % 2
        target = position = error = speed = torque = 0.0
        if kind == 0:
            target = axis.target()
            if abs(target) == float("inf"):
                target = axis.command_position()
        elif kind == 2:
            position = axis.position()
        elif kind == 4:
            error = axis.position_error()
        elif kind == 6:
            speed = axis.velocity()
        elif kind == 8:
            torque = float(self.torque())
        return output_volts(k35, target=target, position=position, error=error,
                            speed_pps=speed, torque=torque,
                            pulses_per_rev=self.resolution.pulses_per_rev)

    def analog_output(self) -> int:
        """The analog output as the Modbus register reads it (K78+54): 0..1023."""
        return volts_to_register(self.analog_output_volts())


if TYPE_CHECKING:
    def _meets_its_protocol(motor: Motor) -> MotorCore:
        """For mypy (tests/test_quality.py): the façade is what its parts see of it."""
        return motor
