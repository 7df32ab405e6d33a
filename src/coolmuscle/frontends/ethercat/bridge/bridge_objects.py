"""The drive's behaviour on the object dictionary: the SDO hooks of 6000h-7FFFh and
F5xxh (ethercat-bridge-users-guide.txt 6.2-6.5, 7.2-7.5, Appendix 6).

The entries themselves (index, type, access, availability) are the Appendix 6 table
(:mod:`.table`); this module only attaches behaviour with
:meth:`~..engine.dictionary.Dictionary.on_read` / ``on_write``.  Hooks run in the frame
thread: they check a value against the manual (abort codes of 5.4.1), answer from
what the model thread last published, and queue the model calls on the axis'
``requests`` for its next cycle.

Range checks of K parameters use the motor's own parameter table (the spec, not its
behaviour): a K write the motor would refuse is refused with 06090031h (too high),
06090032h (too low) or 06090030h (not a value of the parameter).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from ....motor.state.firmware import get_firmware
from ....motor.state.memory import H_RANGE
from ..engine.dictionary import (
    DEVICE_STATE,
    VALUE_HIGH,
    VALUE_LOW,
    VALUE_RANGE,
    Dictionary,
    SdoAbort,
)
from . import cpio, homing, modes
from .cia402 import State
from .link import BAUD_CODE, CYCLE_CODE

if TYPE_CHECKING:
    from .axis import AxisDrive
    from .cml_mailbox import CmlMailbox

K_FIRST = 21                 # 60F6h subindex 1h = K21 (7.5)


class Drive(Protocol):
    """What the hooks reach of the drive (:class:`~.drive.BridgeDrive`, which registers
    them: it imports this module, so this module sees it through this protocol)."""

    od: Dictionary
    firmware: tuple[str, ...]
    axes: dict[int, AxisDrive]
    mailboxes: dict[int, CmlMailbox]

    def system_info(self, sub: int) -> int: ...


def signed32(value: int) -> int:
    """A UINT32 entry carrying a signed K value (K48, K58 ...)."""
    return value - (1 << 32) if value >= 1 << 31 else value


def check_k(firmware: str, k: int, value: int) -> None:
    """Refuse a K value the motor's table does not accept (5.4.1 codes)."""
    try:
        spec = get_firmware(firmware).spec(k)
    except KeyError:
        raise SdoAbort(VALUE_RANGE, f"K{k}") from None
    if spec.accepts(value):
        return
    if spec.kind == "range":
        raise SdoAbort(VALUE_HIGH if value > spec.max else VALUE_LOW, f"K{k}={value}")
    raise SdoAbort(VALUE_RANGE, f"K{k}={value}")


def register(drive: Drive) -> None:
    """Attach every hook of ``drive`` (a :class:`~.drive.BridgeDrive`) to the dictionary."""
    od = drive.od
    for axis in drive.axes.values():
        _axis_hooks(od, axis, drive)
    od.on_read(0xF530, drive.system_info)
    for n in range(1, 5):
        fw = drive.firmware[n - 1]
        od.set(0xF510 + n, 1, 1 if fw == "cm1" else 2)     # 7.3 CM type
        od.set(0xF510 + n, 2, BAUD_CODE)                    # "6: 176,800bps"
        od.set(0xF510 + n, 3, CYCLE_CODE)                   # "1: 1 msec"


def _axis_hooks(od: Dictionary, axis: AxisDrive, drive: Drive) -> None:
    i = axis.idx
    od.on_write(i(0x6060), lambda sub, v: _mode(axis, int(v)))
    od.on_write(i(0x6098), lambda sub, v: _method(int(v)))
    od.on_write(i(0x6099), lambda sub, v: check_k(axis.firmware, 42, int(v)))
    _k_object(od, i(0x609A), axis, 43)
    _k_object(od, i(0x607C), axis, 48)
    od.on_read(i(0x60F6), lambda sub: _k_read(axis, sub))
    od.on_write(i(0x60F6), lambda sub, v: _k_write(axis, K_FIRST - 1 + sub, signed32(int(v))))
    if axis.firmware != "cm1":
        od.on_read(i(0x60FB), lambda sub: axis.h0 if sub == 1 else 0x0A)
        od.on_write(i(0x60FB), lambda sub, v: _stiffness(axis, int(v)))
    od.on_read(i(0x60FD), lambda sub: _inputs(axis))
    od.on_write(i(0x60FE), lambda sub, v: _outputs(od, axis, sub, int(v)))
    mailbox = drive.mailboxes[axis.motor]
    od.on_write(0xF580 + axis.motor, lambda sub, v: _cml(axis, mailbox, str(v)))
    od.on_read(0xF590 + axis.motor, lambda sub: mailbox.read())


def _mode(axis: AxisDrive, value: int) -> int:
    """6060h: the mode requested; the value kept is the mode it selects (6.2.2 note 3)."""
    try:
        axis.request_mode(value)
    except ValueError as exc:
        raise SdoAbort(DEVICE_STATE, str(exc)) from None
    return modes.resolve(value)


def _method(value: int) -> None:
    if value not in homing.METHODS:
        raise SdoAbort(VALUE_HIGH if value > homing.METHODS[-1] else VALUE_LOW,
                       f"homing method {value}")


def _k_object(od: Dictionary, index: int, axis: AxisDrive, k: int) -> None:
    """609Ah (K43), 607Ch (K48): the object is the motor's K parameter (6.4.1), a U32
    that carries a signed K as 60F6h does (K48 = -5 reads FFFFFFFBh)."""
    od.on_read(index, lambda sub: axis.k.get(k, 0) & 0xFFFFFFFF)   # a U32 carrying K
    od.on_write(index, lambda sub, v: _k_write(axis, k, signed32(int(v))))


def _k_read(axis: AxisDrive, sub: int) -> int:
    if sub == 0:
        return 0x4F
    return axis.k.get(K_FIRST - 1 + sub, 0) & 0xFFFFFFFF


def _k_write(axis: AxisDrive, k: int, value: int) -> None:
    """7.5: the K value goes to the motor, which keeps it (its writes persist)."""
    check_k(axis.firmware, k, value)
    axis.k[k] = value
    axis.requests.append(lambda: axis.set_k(k, value))


def _stiffness(axis: AxisDrive, value: int) -> None:
    """60FBh.1: the CM2 servo stiffness H0 (cml-users-guide.txt K78+670)."""
    if not H_RANGE[0] <= value <= H_RANGE[1]:
        raise SdoAbort(VALUE_HIGH if value > H_RANGE[1] else VALUE_LOW, f"H0={value}")
    axis.h0 = value
    axis.requests.append(lambda: axis.device.set_register(axis.motor, "H", 0, value))


def _io_available(axis: AxisDrive) -> None:
    """6.5: "available when operation mode is csp mode and Cool Muscle is motor enable
    (state B or C)"."""
    if axis.mode != modes.CSP or axis.state not in (State.SWITCHED_ON,
                                                     State.OPERATION_ENABLED):
        raise SdoAbort(DEVICE_STATE, "digital I/O needs csp in state B or C (6.5)")


def _inputs(axis: AxisDrive) -> int:
    _io_available(axis)
    return axis.inputs & cpio.input_mask(axis.firmware)


def _outputs(od: Dictionary, axis: AxisDrive, sub: int, value: int) -> None:
    _io_available(axis)
    physical = value if sub == 1 else int(od.get(axis.idx(0x60FE), 1))
    mask = value if sub == 2 else int(od.get(axis.idx(0x60FE), 2))
    axis.requests.append(lambda: axis.set_outputs(physical & mask))


def _cml(axis: AxisDrive, mailbox: CmlMailbox, text: str) -> None:
    """F58xh: a CML string, in CML mode (7.1.1)."""
    if axis.mode != modes.CML:
        raise SdoAbort(DEVICE_STATE, "CML strings need CML mode (6060h = 101)")
    mailbox.submit(text)
