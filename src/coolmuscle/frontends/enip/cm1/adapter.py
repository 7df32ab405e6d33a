"""The CM1 EtherNet/IP module itself (cm1-ethernetip-interface-manual.txt ch. 3).

The real module is a gateway: it holds the two assembly images and talks to the
motor over the motor's serial line.  :class:`Cm1Module` does the same through the
device API (``cyclic_state``, ``set_register``, ``execute``, ``set_param``); it never
moves a motor itself.

* Input image (3.1): bytes 0-1 communication error code, 2-3 motor status code (the
  motor's ``Ux``, 3.1.2 uses its values), 4-7 position (``Px``), little endian.
* Output image (3.2): all zero at power-up.  Nothing reaches the motor while the
  run/idle flag (bytes 0-1, 3.2.1) is not 1, or while the Class 1 run/idle header
  says idle.
* The control word (byte 12, 3.2.3) acts when its value changes, as a PLC toggling
  through 0 expects: 1 writes P0/S0/A0 (bytes 2-5, 6-9, 10-11) and starts the move
  (``^``), 2 sets A0 and stops with that deceleration (``]1``), 3 enables (``(``), 4
  frees (``)``), 5 starts the origin search (``|``).  A value written while idle
  acts when the flag turns to run.
* Byte 13 (3.2.4): changing to 1 sets K52=10; 0 leaves K52 as it is.
* Communication error code (3.1.1): bit 0 when the motor refused a value (an
  ``OutOfRangeError`` of the device API), bit 1 when the serial line timed out after
  working, bit 2 when it never worked; the last two come from
  :meth:`Cm1Module.serial_fault`, the module's own link, or from the device's wire
  faults (the ``enip`` door's ``serial_link``; the motor powered off times the line
  out; ``errors`` sets bit 0 until cleared).  While the
  line is faulted the input image keeps its last motor values and writes are not
  delivered.

Every choice where the manual is silent is in docs/fidelity.md "EtherNet/IP".
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from typing import Any, Literal

from ....device import Device
from ....device.wire.chain import cut_from
from ....errors import CoolMuscleError
from ..cip.io import IoState

log = logging.getLogger(__name__)

OUTPUT_SIZE = 14
INPUT = struct.Struct("<HHI")
OUTPUT = struct.Struct("<HiihBB")      # A0 a signed short (3.2.2 "Short Integer")

ERR_MOTOR_ERROR = 0x0001
ERR_TIMED_OUT = 0x0002
ERR_NEVER = 0x0004

SerialState = Literal["ok", "errors", "timeout", "absent"]

_SERIAL_STATES: dict[str, SerialState] = {"timeout": "timeout", "absent": "absent",
                                          "errors": "errors"}

#: Control word value -> the CML action sent to the motor (3.2.3).
ACTIONS = {3: "(", 4: ")", 5: "|"}


class Cm1Module:
    """The module between the EtherNet/IP objects and one motor of a device."""

    def __init__(self, device: Device, motor: int = 1) -> None:
        self.device = device
        self.motor = motor
        self._output = bytearray(OUTPUT_SIZE)
        self._acted_control = 0
        self._acted_k52 = 0
        self._refused = False
        self._serial: SerialState = "ok"      # set by serial_fault()
        self.header_run = True
        self.io_state: IoState = "none"
        self._last = (0, 0)
        self.commands = 0

    @property
    def serial(self) -> SerialState:
        """The module's serial link to the motor now: a wire fault of the ``enip`` door
        (``serial_link``), the motor cut off by the chain's faults (powered off: the
        line times out), else what :meth:`serial_fault` set (docs/wire-faults.md)."""
        faults = self.device.wire_faults
        if faults.live("enip"):
            fault = faults.lasting("enip", "serial_link")
            if fault is not None:
                return _SERIAL_STATES[str(fault.params["state"])]
        if faults.live("chain"):
            cut = cut_from(faults)
            if cut and self.motor >= cut:
                return "timeout"
        return self._serial

    # -- the images ----------------------------------------------------------------------
    def input_image(self) -> bytes:
        """The 8 bytes of assembly 0x65 now (3.1)."""
        if self.serial == "ok":
            state = self.device.cyclic_state(self.motor)
            self._last = (state.status & 0xFFFF, state.position & 0xFFFFFFFF)
        return INPUT.pack(self.comm_error(), *self._last)

    def output_image(self) -> bytes:
        return bytes(self._output)

    def comm_error(self) -> int:
        """The communication error code of 3.1.1 (also class 0x64 attribute 0x64)."""
        code = ERR_MOTOR_ERROR if self._refused or self.serial == "errors" else 0
        if self.serial == "timeout":
            code |= ERR_TIMED_OUT
        elif self.serial == "absent":
            code |= ERR_NEVER
        return code

    def identity_status(self) -> int:
        """Identity attribute 5: owned, extended device status, minor fault (CIP 5A-2.2)."""
        ext = {"none": 3, "run": 6, "idle": 7, "faulted": 2}[self.io_state]
        owned = 0 if self.io_state in ("none", "faulted") else 1
        minor = 0x0100 if self.comm_error() & 0x0007 else 0
        return owned | 0x0004 | (ext << 4) | minor

    # -- writes ---------------------------------------------------------------------------
    def write_output(self, data: bytes, run: bool = True) -> None:
        """New output data (Set_Attribute_Single or an O->T packet); applies 3.2 rules."""
        self._output[:] = bytes(data[:OUTPUT_SIZE]).ljust(OUTPUT_SIZE, b"\x00")
        self.header_run = run
        self._apply()

    def reset_outputs(self) -> None:
        """Back to the power-up image (all 0, idle): connection closed or timed out."""
        self._output[:] = bytes(OUTPUT_SIZE)
        self.header_run = True
        self._acted_control = 0
        self._acted_k52 = 0

    @property
    def running(self) -> bool:
        """Writes reach the motor: flag 1 (3.2.1), Class 1 header run, line working."""
        flag = self._output[0] | (self._output[1] << 8)
        return flag == 1 and self.header_run and self.serial == "ok"

    def fields(self) -> tuple[int, int, int, int, int, int]:
        """Flag, P0, S0, A0, control word, K52 byte of the output image."""
        return OUTPUT.unpack(bytes(self._output))

    def _apply(self) -> None:
        if not self.running:
            return
        _, position, speed, accel, control, k52 = self.fields()
        if control != self._acted_control:
            self._acted_control = control
            self._act(control, position, speed, accel)
        if k52 != self._acted_k52:
            self._acted_k52 = k52
            if k52 == 1:
                self._guard(self.device.set_param, self.motor, 52, 10)

    def _act(self, control: int, position: int, speed: int, accel: int) -> None:
        m = self.motor
        if control == 1:
            if (self._guard(self.device.set_register, m, "P", 0, position)
                    and self._guard(self.device.set_register, m, "S", 0, speed)
                    and self._guard(self.device.set_register, m, "A", 0, accel)):
                self._send("^")
        elif control == 2:
            if self._guard(self.device.set_register, m, "A", 0, accel):
                self._send("]1")
        elif control in ACTIONS:
            self._send(ACTIONS[control])

    def _send(self, command: str) -> None:
        self.commands += 1
        self.device.execute(f"{command}.{self.motor}", origin="fieldbus")

    def _guard(self, fn: Callable[..., object], *args: Any) -> bool:
        """One exchange with the motor: an error reply sets bit 0 until the next success."""
        try:
            fn(*args)
        except (CoolMuscleError, ValueError, LookupError) as exc:
            log.info("enip: motor refused %s%r: %s", getattr(fn, "__name__", fn), args, exc)
            self._refused = True
            return False
        self._refused = False
        return True

    # -- the module's serial line -----------------------------------------------------------
    def serial_fault(self, state: SerialState) -> None:
        """Inject a fault on the module-to-motor line: ``ok``, ``errors``, ``timeout``,
        ``absent`` (3.1.1 bits 0, 1, 2)."""
        if state not in ("ok", "errors", "timeout", "absent"):
            raise ValueError(f"unknown serial state {state!r}")
        self._serial = state
        if state == "ok":
            self._refused = False
