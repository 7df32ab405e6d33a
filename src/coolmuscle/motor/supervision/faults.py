"""Fault injection: the device API's ``inject_fault`` and the machine file's fault schedule.

Each fault acts on the model, so the motor answers as it would (docs/machine-file.md
"Faults"; choices in docs/fidelity.md "Servo, load and alarms"):

==================  ===============================================  ==================
fault               what it does                                     parameters
==================  ===============================================  ==================
overload            an extra constant load torque on the shaft       torque (% rated,
                    (a jam); the motor answers with its own          -1000..1000,
                    overload / position error alarms                 default 200), clear
over_temperature    the driver case is at this temperature now;      temperature (°C,
                    it cools by the I²t model                        -40..200, default
                                                                     alarm + 5)
over_current        power module over current: alarm Ux=64 now       —
                    (CM1: 4, its EIP manual's 3.1.2 "Over Current")
regeneration        regenerative over voltage: alarm Ux=2 now        —
over_speed          alias of regeneration (6.6 "over speed/          —
                    regenerative voltage")
supply_voltage      the supply (?72 VSEN) is this many volts; the    volts (default
                    maximum speed scales with it                     half), clear
encoder             the encoder is lost: position error overflow     —
                    (Ux=1) now
stuck_input         input N reads ``on`` whatever drives it          input, on, clear
broken_cable        ``io``: every input reads off electrically;      cable ("io" or
                    ``power``: the motor makes no torque             "power"), clear
==================  ===============================================  ==================

``clear=1`` (or true) undoes a lasting fault.  An unknown fault or parameter is a
``ValueError`` (device API) — nothing is changed then.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Final

from ..status import Ux

if TYPE_CHECKING:
    from ..core import MotorCore

#: Nominal supply, ?72 units of 0.1 V (docs/fidelity.md).
NOMINAL_VSEN: Final = 240
#: Bounds of the injected values: ten times the rated torque either way (a jam, a load
#: driving the shaft); a driver case between a freezer and far past its alarm.  Beyond
#: them a value means nothing physical and would overflow the load model's numbers.
# (not Final: compiled, a Final tuple of floats reads as unset, a mypyc 1.19 fault)
TORQUE_PERCENT = (-1000.0, 1000.0)
TEMPERATURE_C = (-40.0, 200.0)


class Faults:
    """The lasting faults of one motor and the injection entry point."""

    def __init__(self, motor: MotorCore) -> None:
        self.motor = motor
        self.extra_load_percent = 0.0
        self.stuck: dict[int, bool] = {}
        self.io_cable_broken = False
        self.power_cable_broken = False
        self._handlers: dict[str, tuple[Callable[[dict[str, object]], None], set[str]]] = {
            "overload": (self._overload, {"torque", "clear"}),
            "over_temperature": (self._temperature, {"temperature"}),
            "over_current": (lambda p: self._alarm(motor.firmware.over_current_ux), set()),
            "regeneration": (lambda p: self._alarm(Ux.OVER_SPEED), set()),
            "over_speed": (lambda p: self._alarm(Ux.OVER_SPEED), set()),
            "supply_voltage": (self._supply, {"volts", "clear"}),
            "encoder": (lambda p: self._alarm(Ux.POSITION_ERROR_OVERFLOW), set()),
            "stuck_input": (self._stuck, {"input", "on", "clear"}),
            "broken_cable": (self._cable, {"cable", "clear"}),
        }

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._handlers)

    def check(self, fault: str, params: dict[str, object]) -> Callable[[dict[str, object]],
                                                                       None]:
        """The handler of ``fault``; ``ValueError`` for an unknown fault or parameter."""
        entry = self._handlers.get(str(fault).strip().lower())
        if entry is None:
            raise ValueError(f"unknown fault {fault!r} (known: {', '.join(self.names)})")
        handler, allowed = entry
        unknown = set(params) - allowed
        if unknown:
            raise ValueError(f"fault {fault!r} takes no parameter {sorted(unknown)[0]!r}")
        self._check_values(params)
        return handler

    def _check_values(self, p: dict[str, object]) -> None:
        """The values' bounds, before anything changes (a machine file's fault schedule
        is checked when the file is installed, not when the fault comes)."""
        for key, bounds in (("torque", TORQUE_PERCENT), ("temperature", TEMPERATURE_C),
                            ("volts", (0.0, 1000.0))):
            if key in p:
                _number(p, key, 0.0, bounds)
        if "input" in p:
            _number(p, "input", 0.0, (1.0, float(self.motor.io.input_count)))
        if "cable" in p and str(p["cable"]).lower() not in ("io", "power"):
            raise ValueError("broken_cable: cable must be 'io' or 'power'")

    def inject(self, fault: str, **params: object) -> None:
        """Inject ``fault`` now; ``ValueError`` for an unknown fault or parameter."""
        self.check(fault, params)(params)

    # -- handlers ---------------------------------------------------------------
    def _alarm(self, bit: int) -> None:
        self.motor.raise_alarm(int(bit))

    def _overload(self, p: dict[str, object]) -> None:
        self.extra_load_percent = 0.0 if _flag(p, "clear") else _number(
            p, "torque", 200.0, TORQUE_PERCENT)
        self.motor.axis.refresh()

    def _temperature(self, p: dict[str, object]) -> None:
        thermal = self.motor.thermal
        temp = _number(p, "temperature", thermal.alarm + 5.0, TEMPERATURE_C)
        self.motor.set_temperature(temp)

    def _supply(self, p: dict[str, object]) -> None:
        volts = NOMINAL_VSEN / 10.0 if _flag(p, "clear") else _number(
            p, "volts", NOMINAL_VSEN / 20.0, (0.0, 1000.0))
        self.motor.voltage = round(volts * 10)
        self.motor.axis.refresh()

    def _stuck(self, p: dict[str, object]) -> None:
        number = int(_number(p, "input", -1))
        if not 1 <= number <= self.motor.io.input_count:
            raise ValueError(f"stuck_input: input must be 1..{self.motor.io.input_count}")
        if _flag(p, "clear"):
            self.stuck.pop(number, None)
        else:
            self.stuck[number] = _flag(p, "on")
        self.motor.refresh_inputs()

    def _cable(self, p: dict[str, object]) -> None:
        cable = str(p.get("cable", "io")).lower()
        if cable not in ("io", "power"):
            raise ValueError("broken_cable: cable must be 'io' or 'power'")
        broken = not _flag(p, "clear")
        if cable == "io":
            self.io_cable_broken = broken
            self.motor.refresh_inputs()
        else:
            self.power_cable_broken = broken
            self.motor.axis.refresh()

    # -- what the motor asks ---------------------------------------------------------
    def input_level(self, number: int, driven: bool) -> bool:
        """The electrical level input ``number`` shows when ``driven`` is applied."""
        if number in self.stuck:
            return self.stuck[number]
        if self.io_cable_broken:
            return False
        return driven

    def speed_scale(self) -> float:
        """Maximum speed factor from the supply voltage."""
        return max(0.0, self.motor.voltage / NOMINAL_VSEN)


def _number(p: dict[str, object], key: str, default: float,
            bounds: tuple[float, float] = (-math.inf, math.inf)) -> float:
    """Parameter ``key`` as a finite float within ``bounds``; ``ValueError`` if not."""
    value = p.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise ValueError(f"{key} must be a finite number, not {value!r}")
    lo, hi = bounds
    if not lo <= value <= hi:
        raise ValueError(f"{key} must be {lo:g}..{hi:g}, not {value!r}")
    return float(value)


def _flag(p: dict[str, object], key: str) -> bool:
    value = p.get(key, False)
    if isinstance(value, str):
        return value.strip().lower() in ("1", "true", "on", "yes")
    return bool(value)
