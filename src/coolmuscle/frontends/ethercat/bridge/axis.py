"""One axis of the bridge: the CiA402 drive and the Cool Muscle modes behind ID n
(ethercat-bridge-users-guide.txt 6.1-6.5, 7.1).

:class:`AxisDrive` runs in the model's thread once a bridge cycle (1 ms): it takes
the requests the SDO hooks queued (K writes, outputs), reads the motor through the
device API's ``cyclic_state``, applies a pending mode switch (6.2.2: at rest, 5 ms
apart), runs the mode's controlword logic and publishes 6041h, 6061h, 6064h.

* csp / hm / CPIO (CiA402): the table :func:`.cia402.next_state`; into
  state B or C from A send ``(`` (motor enable, which also clears a latched alarm),
  into state A from B or C send ``)`` (motor free); a fault reset leaves the alarm
  latched until the next Switched on enables the motor (6.1.1 State C note 1).
  In Operation enabled csp and CPIO follow
  607Ah (:mod:`.csp`), hm starts the motor's origin search on the 0 -> 1 edge of
  controlword bit 4 (:mod:`.homing`), CPIO sets OUT1-OUT4 from bits 4-7 (:mod:`.cpio`).
* CMD: F107h/F207h/F307h/F407h/F607h send ``)``, ``(``, ``|``, ``|2``, ``]1`` and
  the statusword's high byte acknowledges (7.1.3); other words leave the state.
* CML: the controlword does nothing; CML strings go through the mailbox.

The frame thread only reads plain attributes of this object (mode, moving, the K
cache) and appends to :attr:`requests`.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable
from typing import Final

from ....device import CyclicState, Device
from ....motor.status import ALARM_BITS, Ux
from ..engine.dictionary import Dictionary
from . import cia402, cpio, csp, homing, modes
from .cia402 import State

log = logging.getLogger(__name__)

AXIS_OFFSET: Final = 0x800
#: Final, these and the masks: compiled, a static each, not a module dictionary lookup
#: (read every cycle).
INT32_MIN: Final = -(1 << 31)
INT32_MAX: Final = (1 << 31) - 1
#: The status bits as plain ints (a flag enum's & and | cost a call each, every cycle).
_ALARM_MASK: Final = int(ALARM_BITS)
_STILL_MASK: Final = int(Ux.IN_POSITION) | int(ALARM_BITS)
#: CMD mode: controlword bits 8-11 -> (CML, acknowledgement high byte), 7.1.2 / 7.1.3.
CMD_WORDS: Final = {0x1: (")", 0xF1), 0x2: ("(", 0xF2), 0x3: ("|", 0xF3), 0x4: ("|2", 0xF4),
                    0x6: ("]1", 0xF6)}
ORIGIN_DONE_ACK: Final = 0xF8
ORIGIN_TIMEOUT_ACK: Final = 0xF9
#: (from, to) -> PDS transition number of the 6.1.1 diagram (for logs and tests).
TRANSITIONS: Final = {
    (State.NOT_READY, State.SWITCH_ON_DISABLED): 1,
    (State.SWITCH_ON_DISABLED, State.READY): 2, (State.READY, State.SWITCHED_ON): 3,
    (State.READY, State.OPERATION_ENABLED): 34, (State.SWITCHED_ON, State.OPERATION_ENABLED): 4,
    (State.OPERATION_ENABLED, State.SWITCHED_ON): 5, (State.SWITCHED_ON, State.READY): 6,
    (State.READY, State.SWITCH_ON_DISABLED): 7, (State.OPERATION_ENABLED, State.READY): 8,
    (State.OPERATION_ENABLED, State.SWITCH_ON_DISABLED): 9,
    (State.SWITCHED_ON, State.SWITCH_ON_DISABLED): 10,
    (State.SWITCHED_ON, State.FAULT_REACTION): 13,
    (State.OPERATION_ENABLED, State.FAULT_REACTION): 13,
    (State.FAULT_REACTION, State.FAULT): 14, (State.FAULT, State.SWITCH_ON_DISABLED): 15,
}


class AxisDrive:
    """The drive of motor ``motor`` (1..4) behind the bridge."""

    def __init__(self, motor: int, firmware: str, device: Device, od: Dictionary) -> None:
        self.motor = motor
        self.firmware = firmware
        self.device = device
        self.od = od
        self.base = AXIS_OFFSET * (motor - 1)
        self.state = State.NOT_READY
        self.mode = modes.POWER_UP
        self.pending_mode: int | None = None
        self.last_switch = -modes.SWITCH_INTERVAL_NS
        self.requests: deque[Callable[[], None]] = deque()
        self.follower = csp.Follower(device, motor)
        self.origin = homing.OriginWatch(device, motor)
        self.cmd_ack = 0
        self.outputs_word: int | None = None      # OUT1-4 the bridge last set
        self.transitions: list[int] = []          # PDS transition numbers, for tests
        self.k: dict[int, int] = {}               # K cache for the SDO hooks
        self.h0 = 0
        self.ux = int(Ux.MOTOR_FREE)
        self.enabled = False
        self.moving = False
        self.inputs = 0
        self._prev_cw = 0
        self._target = 0                          # 607Ah of the cycle's output image
        # the places of the entries read and written every cycle (Dictionary.key)
        self._controlword = od.key(self.idx(0x6040))
        self._target_position = od.key(self.idx(0x607A))
        self._statusword = od.key(self.idx(0x6041))
        self._position_actual = od.key(self.idx(0x6064))
        self._mode_display = od.key(self.idx(0x6061))

    # -- helpers ------------------------------------------------------------------
    def idx(self, index: int) -> int:
        """ID1's ``index`` for this axis (Appendix 6: + 0x800 per ID)."""
        return index + self.base

    def send(self, text: str) -> None:
        """A command line of the bridge itself (its replies are not the master's)."""
        self.device.execute(text, origin="api", motor=self.motor)

    @property
    def alarm(self) -> bool:
        return bool(self.ux & _ALARM_MASK)

    # -- the cycle ----------------------------------------------------------------------
    def cycle(self, now: int) -> None:
        while self.requests:
            request = self.requests.popleft()
            try:
                request()
            except Exception:
                log.exception("ID%d: an SDO request failed in the model", self.motor)
        snap = self.device.cyclic_state(self.motor)
        self._observe(snap)
        self._switch_mode(now)
        # 6040h and 607Ah of one output image: read together, before any call into the
        # motor (the frame thread writes the next image between two cycles).
        cw = self.od.value_at(self._controlword)
        self._target = self.od.value_at(self._target_position)
        if modes.is_cia402(self.mode):
            self._cia402(cw, now)
        elif self.mode == modes.CMD:
            self._cmd(cw, now)
        self._watch_origin(snap, now)
        self._prev_cw = cw
        self._publish(snap)

    def _observe(self, snap: CyclicState) -> None:
        self.ux = snap.status
        self.enabled = snap.enabled
        self.inputs = snap.inputs
        if self.outputs_word is None:
            self.outputs_word = snap.outputs & 0x0F
        # Appendix 3 "Confirm Motor is Inposition": an enabled motor moves until Ux says
        # in position; a free one while it still coasts.
        self.moving = bool(self.origin.running
                           or (snap.enabled and not snap.status & _STILL_MASK)
                           or (not snap.enabled and abs(snap.speed_pps) > 1.0))

    def _publish(self, snap: CyclicState) -> None:
        od = self.od
        od.set_at(self._statusword, self.statusword())
        position = int(snap.position)
        od.set_at(self._position_actual, INT32_MIN if position < INT32_MIN
                  else INT32_MAX if position > INT32_MAX else position)
        od.set_at(self._mode_display, self.mode)

    # -- modes (6.2.2) ------------------------------------------------------------------
    def request_mode(self, value: int) -> None:
        """6060h written (frame thread); raises ``ValueError`` when the switch is refused."""
        target = modes.resolve(value)
        base = self.pending_mode if self.pending_mode is not None else self.mode
        if not modes.allowed(base, target):
            raise ValueError(f"{modes.NAMES[base]} cannot switch to {modes.NAMES[target]}")
        if target != base and modes.needs_rest(target) and (self.moving or self.alarm):
            raise ValueError("the motor is not at rest")
        self.pending_mode = target

    def _switch_mode(self, now: int) -> None:
        target = self.pending_mode
        if target is None or now - self.last_switch < modes.SWITCH_INTERVAL_NS:
            return
        if self.pending_mode == target:          # a newer request stays for the next cycle
            self.pending_mode = None
        if target == self.mode:
            return
        self.follower.stop()
        self.origin.abort()
        self.origin.reset()
        self.cmd_ack = 0
        log.info("ID%d: mode %s -> %s", self.motor, modes.NAMES[self.mode], modes.NAMES[target])
        self.mode = target
        self.last_switch = now

    # -- CiA402 (6.1) -----------------------------------------------------------------------
    def _state_bits(self, cw: int) -> int:
        """The CiA402 part of a controlword (a CPIO word's bits 4-7 are outputs)."""
        return cw & 0x000F if self.mode == modes.CPIO and cpio.is_cpio_word(cw) else cw

    def _cia402(self, cw: int, now: int) -> None:
        old = self.state
        new = cia402.next_state(old, self._state_bits(cw), self._state_bits(self._prev_cw),
                                self.alarm)
        if new is not old:
            self.transitions.append(TRANSITIONS.get((old, new), 0))
            self._enter(old, new)
            self.state = new
        if self.state is State.OPERATION_ENABLED:
            if self.mode == modes.HM:
                self._homing(cw, now)
            else:
                self.follower.start()
                self.follower.push(csp.clamp(self._target, self.k.get(37, 0)))
        if self.mode == modes.CPIO and cpio.is_cpio_word(cw) \
                and self.state in (State.SWITCHED_ON, State.OPERATION_ENABLED):
            self.set_outputs(cpio.outputs_of(cw, self.firmware))

    def _enter(self, old: State, new: State) -> None:
        """What a PDS transition does to the Cool Muscle (6.1.1 State A/B/C)."""
        if old is State.OPERATION_ENABLED:
            self.follower.stop()
            self.origin.abort()
        before, after = cia402.motor_state(old), cia402.motor_state(new)
        if after == "A" and before in ("B", "C") and new is not State.FAULT:
            self.send(f").{self.motor}")                      # motor free (6.1.1 A.2)
        elif after in ("B", "C") and before == "A":
            self.send(f"(.{self.motor}")                      # motor enable (6.1.1 B)

    def _homing(self, cw: int, now: int) -> None:
        start, was = cw & 0x10, self._prev_cw & 0x10
        if start and not was:
            self._start_homing(now)
        elif was and not start and self.origin.running:
            self.origin.abort()

    def _start_homing(self, now: int) -> None:
        """Appendix 4.1: the K parameters from the objects, then the motor's ``|``."""
        od, k = self.od, self.k
        params = homing.homing_params(
            int(od.get(self.idx(0x6098))), k.get(45, 0), k.get(46, 0),
            int(od.get(self.idx(0x6099), 1)), int(od.get(self.idx(0x6099), 2)))
        for number, value in params.items():
            if self.k.get(number) != value:
                self.set_k(number, value)
        self.origin.start(now)

    def _watch_origin(self, snap: CyclicState, now: int) -> None:
        phase = self.origin.update(snap, now)
        if self.mode == modes.CMD and self.cmd_ack == 0xF3:
            if phase == homing.ATTAINED:
                self.cmd_ack = ORIGIN_DONE_ACK
            elif phase in (homing.ERROR, homing.INTERRUPTED):
                self.cmd_ack = ORIGIN_TIMEOUT_ACK

    # -- CMD mode (7.1.2) ----------------------------------------------------------------------
    def _cmd(self, cw: int, now: int) -> None:
        if cw & 0xF000 != 0xF000:
            self.cmd_ack = 0
            return
        if cw == self._prev_cw:
            return
        word = CMD_WORDS.get((cw >> 8) & 0x0F)
        if word is None or cw & 0x00FF not in (0x00, 0x07):
            self.cmd_ack = 0
            return
        cml, ack = word
        if cml == "|":
            self.origin.start(now)
        elif cml == "]1":
            self.origin.abort()
            self.send(f"]1.{self.motor}")
        else:
            self.send(f"{cml}.{self.motor}")
        self.cmd_ack = ack

    # -- outputs (6.5.2, 7.1.2) -----------------------------------------------------------------
    def set_outputs(self, word: int) -> None:
        """Drive OUT1-OUT4 to ``word`` (only the outputs the motor lends the bridge)."""
        mask = cpio.output_mask(self.firmware)
        old = self.outputs_word if self.outputs_word is not None else 0
        line = cpio.output_commands(self.motor, old, word & mask, mask)
        if line:
            self.send(line)
        self.outputs_word = (old & ~mask) | (word & mask)

    def set_k(self, k: int, value: int) -> None:
        """A K parameter write (model thread); the cache follows."""
        self.device.set_param(self.motor, k, value)
        self.k[k] = value

    def outputs_lost(self) -> None:
        """OP was left: the output image is no longer valid; stop following (hold)."""
        if self.state is State.OPERATION_ENABLED:
            self.transitions.append(5)
            self._enter(self.state, State.SWITCHED_ON)
            self.state = State.SWITCHED_ON
        self._prev_cw = int(self.od.get(self.idx(0x6040)))

    # -- statusword (6.1.3, 6.4.2, 7.1.3) ----------------------------------------------------------
    def statusword(self) -> int:
        csp_following = self.mode == modes.CSP and self.follower.active
        sw = cia402.statusword(self.state, csp=csp_following, alarm=self.alarm,
                               free=not self.enabled)
        if self.mode == modes.CPIO:
            return cpio.statusword(sw, self.ux, self.inputs, self.firmware)
        if self.mode == modes.CMD and self.cmd_ack:
            return self.cmd_ack << 8
        if self.mode == modes.HM:
            sw |= homing.STATUS_BITS[self.origin.phase]
        return sw
