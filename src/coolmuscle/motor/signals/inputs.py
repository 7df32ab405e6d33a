"""Input functions of one motor (cml-users-guide.txt ch. 3 K25-K32, K36; 5.1).

Each input gives two signals (K25): the *quick* response signal is the input signal
itself (after the K26 logic, :mod:`.io`); the *slow* response signal comes on when the
quick one has stayed on for the K25 delay (0.1 s units, one digit per input) and goes
off with it.  "When a signal disappears within the offset time, only a Quick Response
Signal is recognized."  Functions are assigned per input, one digit each:

* at the level of the quick / slow signal (K27 / K30): general use, origin sensor,
  manual feed CW / CCW, stop ladder, CW / CCW limit, emergency stop, stop program bank;
* at the rising edge (K28 / K31) and the falling edge (K29 / K32): alarm reset and
  program pause, motor free (rising) / enable (falling), position counter reset, next /
  previous line, program bank 1, origin search, jog CW / CCW (program bank 2 / 3 when
  K36 = 2 or 3).

Edges run their functions at the instant the signal changes (a kernel event for the
slow signal); the motor actions are those of :mod:`.motor`, the program ones those of
:mod:`.program`.  Choices where the manual is silent: docs/fidelity.md "Inputs and outputs".

P type operation (ch. 3 K26 digits 2/3, K36): the command pulse train on inputs 1 and
2 moves the commanded position one pulse per effective edge (the rising edge of the
input *signal*: K26 0/2 is the port's rising edge, 1/3 its falling edge, which is the
signal's rising edge); K36 0/2 CW/CCW (input 1 CW, input 2 CCW), 1/3 pulse/direction
(input 1 the pulses, input 2 ON for CW).  Always, when input 1 or 2 has digit 2/3;
while an input 3..6 with digit 2/3 is ON and no program bank runs, otherwise.  A
command from the host has priority: pulses wait while its motion runs.
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

from ...cml import ast
from ...sim.kernel import NS_PER_MS, PRIO_IO, Timer
from .io import digit

if TYPE_CHECKING:
    from ..context import Context
    from ..core import MotorCore

# K27/K30 level functions (ch. 3 K27)
LV_GENERAL, LV_ORIGIN, LV_FEED_CW, LV_FEED_CCW, LV_STOP_LADDER = 1, 2, 3, 4, 5
LV_CW_LIMIT, LV_ESTOP, LV_STOP_BANK, LV_CCW_LIMIT = 6, 7, 8, 9
# K28/K29/K31/K32 edge functions (ch. 3 K28)
ED_RESET_PAUSE, ED_FREE_ENABLE, ED_COUNTER_RESET, ED_NEXT, ED_PREVIOUS = 1, 2, 3, 4, 5
ED_BANK1, ED_ORIGIN, ED_JOG_CW, ED_JOG_CCW = 6, 7, 8, 9

QUICK_LEVEL, QUICK_RISE, QUICK_FALL, SLOW_LEVEL, SLOW_RISE, SLOW_FALL = 27, 28, 29, 30, 31, 32


class InputFunctions:
    """Quick and slow signals of every input and the functions they run."""

    def __init__(self, motor: MotorCore) -> None:
        self.motor = motor
        count = motor.io.input_count
        self.quick = [False] * (count + 1)
        self.slow = [False] * (count + 1)
        self._timers: list[Timer | None] = [None] * (count + 1)
        self._ctx: Context | None = None
        self._p_profile: object = None      # the command the last P type pulse gave

    @property
    def ctx(self) -> Context:
        if self._ctx is None:
            from ..context import Context
            self._ctx = Context(origin="motor", default_motor=self.motor.id)
        return self._ctx

    # -- what other parts ask ------------------------------------------------------
    def function(self, k: int, number: int) -> int:
        """The function digit of input ``number`` in K``k``."""
        return digit(self.motor.k(k), number)

    def level_on(self, function: int) -> bool:
        """Whether an input with level function ``function`` (K27 or K30) is on now."""
        for n in range(1, len(self.quick)):
            if (self.quick[n] and self.function(QUICK_LEVEL, n) == function) or (
                    self.slow[n] and self.function(SLOW_LEVEL, n) == function):
                return True
        return False

    def origin_sensor(self) -> bool:
        """K27 function 2: the origin sensor signal (5.3.2)."""
        return self.level_on(LV_ORIGIN)

    def ladder_held(self) -> bool:
        """Function 5 "Stop Ladder Logic Bank" is on: no ladder bank may run."""
        return self.level_on(LV_STOP_LADDER)

    def estop_held(self) -> bool:
        """Function 7: "Emergency Stop can not be canceled by CML command" while on."""
        return self.level_on(LV_ESTOP)

    def delay_ns(self, number: int) -> int:
        """K25: the slow-signal delay of input ``number`` (0.1 s units, one digit each)."""
        k25 = self.motor.k(25)
        spec = self.motor.firmware.spec(25)
        value = digit(k25, number) if spec.kind == "digits" else k25
        return value * 100 * NS_PER_MS

    # -- signal changes ------------------------------------------------------------------
    def signal_changed(self, number: int) -> None:
        """The quick signal of input ``number`` may have changed (level, K26)."""
        on = self.motor.io.input_signal(number)
        if on == self.quick[number]:
            return
        self.quick[number] = on
        if on:
            if number <= 2:
                self._command_pulse(number)
            self._level(QUICK_LEVEL, number, True)
            self._edge(QUICK_RISE, number, rising=True)
            self._timers[number] = self.motor.kernel.schedule(
                self.delay_ns(number), lambda: self._slow_on(number), priority=PRIO_IO,
                name=f"slow-input-{number}")
            return
        timer, self._timers[number] = self._timers[number], None
        if timer is not None:
            timer.cancel()
        self._level(QUICK_LEVEL, number, False)
        self._edge(QUICK_FALL, number, rising=False)
        if self.slow[number]:
            self.slow[number] = False
            self._level(SLOW_LEVEL, number, False)
            self._edge(SLOW_FALL, number, rising=False)

    # -- P type operation (ch. 3 K26 ②, K36) --------------------------------------------
    def p_type_always(self) -> bool:
        """K26 digit 2/3 on input 1 or 2: "P type Operation is executed at all times"."""
        k26 = self.motor.k(26)
        return digit(k26, 1) in (2, 3) or digit(k26, 2) in (2, 3)

    def p_type_active(self) -> bool:
        """Whether command pulses on inputs 1 and 2 move the motor now (ch. 3 K26 ②)."""
        if self.p_type_always():
            return True
        if self.motor.program.state != "idle":  # "During the execution of Bank Program,
            return False    # it can not be switched to P type Operation even if ... ON"
        k26 = self.motor.k(26)
        return any(self.quick[n] and digit(k26, n) in (2, 3)
                   for n in range(3, len(self.quick)))

    def _command_pulse(self, number: int) -> None:
        """An effective edge on input 1 or 2 (K36 format): one pulse of command."""
        if not self.p_type_active():
            return
        if self.motor.k(36) % 2 == 0:            # CW/CCW pulses
            step = 1 if number == 1 else -1
        elif number == 1:                        # pulse/direction: input 2 ON is CW
            step = 1 if self.quick[2] else -1
        else:
            return
        m = self.motor
        axis = m.axis
        if axis.moving and axis.profile is not self._p_profile:
            return                               # a host command's motion has priority
        m.follow(axis.target() + step)
        self._p_profile = axis.profile

    def _slow_on(self, number: int) -> None:
        self._timers[number] = None
        if not self.quick[number]:
            return
        self.slow[number] = True
        self._level(SLOW_LEVEL, number, True)
        self._edge(SLOW_RISE, number, rising=True)
        self.motor.bus.poke()

    def power_up(self) -> None:
        """Inputs already on at power-up hold their level functions (no edges)."""
        for number in range(1, len(self.quick)):
            if self.motor.io.input_signal(number) and not self.quick[number]:
                self.quick[number] = True
                self._level(QUICK_LEVEL, number, True)
                self._timers[number] = self.motor.kernel.schedule(
                    self.delay_ns(number), partial(self._slow_on, number),
                    priority=PRIO_IO, name=f"slow-input-{number}")

    # -- functions ---------------------------------------------------------------------
    def _level(self, k: int, number: int, on: bool) -> None:
        """K27/K30 functions at the target level (on) and when it ends (off)."""
        fn = self.function(k, number)
        m = self.motor
        if fn in (LV_FEED_CW, LV_FEED_CCW):
            if on:
                m.feed(1 if fn == LV_FEED_CW else -1)
            else:
                m.feed_stop()
        elif fn in (LV_CW_LIMIT, LV_CCW_LIMIT):
            m.limit_sensor(1 if fn == LV_CW_LIMIT else -1, on)
        elif fn == LV_STOP_LADDER and on:
            m.ladder.stop()
            m.logic_motion.stop()
        elif fn == LV_ESTOP:
            self._estop(on)
        elif fn == LV_STOP_BANK and on:
            for _ in range(2):   # "Same as ]] command"
                m.bus.chain_command(m, ast.Exec("pause", m.id), self.ctx)

    def _estop(self, on: bool) -> None:
        m = self.motor
        if on:
            m.emergency_stop()
            m.program.emergency()
        elif not self.estop_held():
            m.emergency_release(force=True)
            m.program.emergency_released()

    def _edge(self, k: int, number: int, *, rising: bool) -> None:
        """K28/K31 (rising) and K29/K32 (falling) edge functions."""
        fn = self.function(k, number)
        m = self.motor
        program = m.program
        if fn == ED_RESET_PAUSE:
            m.reset_alarm()
            if program.state in ("running", "stepping"):
                program.pause()
            m.stop()
        elif fn == ED_FREE_ENABLE:
            m.free() if rising else m.enable()
        elif fn == ED_COUNTER_RESET:
            m.set_origin()
        elif fn == ED_NEXT:
            program.next_line(self.ctx)
        elif fn == ED_PREVIOUS:
            program.prev_line(self.ctx)
        elif fn == ED_BANK1:
            program.resume() if program.state == "paused" else program.start(1, self.ctx)
        elif fn == ED_ORIGIN:
            m.origin_search()
        elif fn in (ED_JOG_CW, ED_JOG_CCW):
            self._jog_or_bank(fn)

    def _jog_or_bank(self, fn: int) -> None:
        m = self.motor
        if m.k(36) in (2, 3):
            m.program.start(2 if fn == ED_JOG_CW else 3, self.ctx)
        else:
            m.jog(1 if fn == ED_JOG_CW else -1)
