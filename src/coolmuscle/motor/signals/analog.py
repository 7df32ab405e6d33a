"""Analog input signals: the voltage at a motor's analog input over virtual time.

This module owns the :class:`AnalogSource` kinds (constant, ramp, sine, CSV file and
a torque sensor on a spring load), the 10-bit converter (:func:`adc`), the per-motor
:class:`AnalogInput` (which source drives the input from when) and
:func:`source_from_config`, which builds a source from the machine file's
``[axis.analog]`` table (docs/machine-file.md).

ADC (cml-users-guide.txt ch. 3 K38): "The analog input voltage 0 to 5V is divided
into 1024, and utilized as an analog control command from 0 to 1023"; ``?74``
(6.6) and the V state ``ADIN`` read that count.  Every source is a closed-form
function of time, evaluated when read; the control loop that samples it lives in
:mod:`.analog_control`.
"""

from __future__ import annotations

import csv
import math
from bisect import bisect_right
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...sim.kernel import NS_PER_S

if TYPE_CHECKING:
    from ..core import MotorCore

FULL_SCALE_V = 5.0
COUNTS = 1024
MAX_COUNT = COUNTS - 1


def counts_to_volts(counts: float) -> float:
    """ADC counts to volts (5 V / 1024 per count)."""
    return counts * FULL_SCALE_V / COUNTS


def volts_to_counts(volts: float) -> float:
    """Volts to (fractional) ADC counts."""
    return volts * COUNTS / FULL_SCALE_V


def adc(volts: float) -> int:
    """The converter: 0..5 V -> 0..1023, truncating, clamped (ch. 3 K38)."""
    if not math.isfinite(volts):
        return 0 if math.isnan(volts) or volts < 0 else MAX_COUNT
    return max(0, min(MAX_COUNT, math.floor(volts_to_counts(volts) + 1e-9)))


class AnalogSource:
    """A voltage as a function of kernel time (ns).

    ``changing(t)``: whether the value may change right after ``t``;
    ``next_change(t)``: the first instant >= ``t`` at which it starts changing
    (``None``: never again).  The control loop sleeps while neither holds.
    """

    def volts(self, t: int) -> float:
        raise NotImplementedError

    def changing(self, t: int) -> bool:
        return False

    def next_change(self, t: int) -> int | None:
        return None

    def bind(self, motor: MotorCore) -> None:
        """Attach to the motor whose input it drives (sensors read the motor)."""

    def load_torque(self, t: int | None = None) -> float:
        """Torque (N·m, raw direction, resisting) the measured load puts on the shaft."""
        return 0.0


@dataclass
class Constant(AnalogSource):
    """A fixed voltage (device API ``set_analog``, script ``@analog``)."""

    value: float = 0.0

    def volts(self, t: int) -> float:
        return self.value


@dataclass
class Ramp(AnalogSource):
    """``start_v`` until ``start``, linear to ``end_v`` over ``duration``, then held."""

    start_v: float
    end_v: float
    start: int          # ns
    duration: int       # ns, > 0

    def volts(self, t: int) -> float:
        if t <= self.start:
            return self.start_v
        if t >= self.start + self.duration:
            return self.end_v
        return self.start_v + (self.end_v - self.start_v) * (t - self.start) / self.duration

    def changing(self, t: int) -> bool:
        return self.start_v != self.end_v and self.start <= t < self.start + self.duration

    def next_change(self, t: int) -> int | None:
        if self.start_v == self.end_v or t >= self.start + self.duration:
            return None
        return max(t, self.start)


@dataclass
class Sine(AnalogSource):
    """``offset + amplitude * sin(2π f t + phase)`` volts."""

    offset: float
    amplitude: float
    frequency: float    # Hz
    phase: float = 0.0  # degrees

    def volts(self, t: int) -> float:
        angle = 2 * math.pi * self.frequency * t / NS_PER_S + math.radians(self.phase)
        return self.offset + self.amplitude * math.sin(angle)

    def _live(self) -> bool:
        return self.amplitude != 0.0 and self.frequency != 0.0

    def changing(self, t: int) -> bool:
        return self._live()

    def next_change(self, t: int) -> int | None:
        return t if self._live() else None


class Table(AnalogSource):
    """Samples (time s, volts): linear or step interpolation, held or repeated."""

    def __init__(self, points: Sequence[tuple[float, float]], *, interpolate: str = "linear",
                 repeat: bool = False, origin: int = 0) -> None:
        if not points:
            raise ValueError("an analog table needs at least one (time, value) row")
        if interpolate not in ("linear", "step"):
            raise ValueError(f"interpolate must be 'linear' or 'step', not {interpolate!r}")
        pts = sorted((float(t), float(v)) for t, v in points)
        self.times = [round(t * NS_PER_S) for t, _ in pts]
        self.values = [v for _, v in pts]
        self.step = interpolate == "step"
        self.origin = origin
        self.period = self.times[-1] if repeat and self.times[-1] > 0 else 0

    def _local(self, t: int) -> int:
        rel = t - self.origin
        if self.period and rel > self.times[-1]:
            rel %= self.period
        return rel

    def volts(self, t: int) -> float:
        rel = self._local(t)
        i = bisect_right(self.times, rel) - 1
        if i < 0:
            return self.values[0]
        if i >= len(self.times) - 1 or self.step:
            return self.values[i]
        t0, t1 = self.times[i], self.times[i + 1]
        v0, v1 = self.values[i], self.values[i + 1]
        return v0 + (v1 - v0) * (rel - t0) / (t1 - t0) if t1 > t0 else v1

    def changing(self, t: int) -> bool:
        rel = self._local(t)
        if self.period:
            return len(set(self.values)) > 1
        i = bisect_right(self.times, rel) - 1
        if i < 0 or i >= len(self.times) - 1:
            return False
        return not self.step and self.values[i] != self.values[i + 1]

    def next_change(self, t: int) -> int | None:
        if self.period:
            return t if len(set(self.values)) > 1 else None
        rel = t - self.origin
        for i in range(len(self.times) - 1):
            if self.values[i] == self.values[i + 1]:
                continue
            if self.step and self.times[i + 1] > rel:
                return self.origin + self.times[i + 1]          # a jump, later
            if not self.step and self.times[i + 1] > rel:
                return self.origin + max(self.times[i], rel)    # a slope, now or later
        return None


class TorqueSensor(AnalogSource):
    """A torque sensor on a spring load (5.5): the motor pushes the load at ``contact``.

    Torque (N·m) = ``stiffness`` x how far the actual shaft (raw pulses: a machine
    position, unmoved by ``|2``) is past ``contact`` in the ``direction`` of the push
    (0 before contact); volts = ``offset`` + ``volts_per_nm`` x torque.  5.5's sensor:
    2.5 V offset, 1 V per 0.2 N·m.
    """

    def __init__(self, *, offset: float = 2.5, volts_per_nm: float = 5.0,
                 stiffness: float = 1e-4, contact: float = 0.0, direction: int = 1) -> None:
        self.offset = offset
        self.volts_per_nm = volts_per_nm
        self.stiffness = stiffness
        self.contact = contact
        self.direction = 1 if direction >= 0 else -1
        self._position: Callable[[int | None], float] = lambda t: 0.0

    def bind(self, motor: MotorCore) -> None:
        def raw(t: int | None) -> float:
            if t is None or t >= motor.kernel.now:
                return motor.axis.raw_actual()
            return motor.timeline.piece_at(t).raw_position(t)
        self._position = raw

    def torque(self, t: int | None = None) -> float:
        """The sensed torque (N·m, >= 0) with the shaft where it is (was) at ``t``."""
        past = (self._position(t) - self.contact) * self.direction
        return self.stiffness * max(0.0, past)

    def load_torque(self, t: int | None = None) -> float:
        """In the raw (CW) direction; the torque control turns it to user terms."""
        return self.direction * self.torque(t)

    def volts(self, t: int) -> float:
        return self.offset + self.volts_per_nm * self.torque(t)

    def changing(self, t: int) -> bool:
        return True

    def next_change(self, t: int) -> int | None:
        return t


class AnalogInput:
    """Which source drives one motor's analog input since when (kept for traces)."""

    def __init__(self, now: Callable[[], int]) -> None:
        self._now = now
        self.since: list[int] = [now()]
        self.sources: list[AnalogSource] = [Constant(0.0)]
        self.recording = False
        self.listeners: list[Callable[[], None]] = []

    @property
    def source(self) -> AnalogSource:
        return self.sources[-1]

    def set_source(self, source: AnalogSource) -> None:
        """Drive the input from ``source`` from now on."""
        now = self._now()
        if not self.recording:
            self.since, self.sources = [], []
        elif self.since and self.since[-1] == now:
            self.since.pop()
            self.sources.pop()
        self.since.append(now)
        self.sources.append(source)
        for listener in tuple(self.listeners):
            listener()

    def set_counts(self, counts: int) -> None:
        """A constant input of ``counts`` (device API ``set_analog``)."""
        self.set_source(Constant(counts_to_volts(counts + 0.5)))

    def source_at(self, t: int) -> AnalogSource:
        i = bisect_right(self.since, t) - 1
        return self.sources[max(i, 0)]

    def volts(self, t: int | None = None) -> float:
        t = self._now() if t is None else t
        return self.source_at(t).volts(t)

    def counts(self, t: int | None = None) -> int:
        """The converter's reading (?74 ``ADI0``)."""
        return adc(self.volts(t))

    def source_load_torque(self, t: int | None = None) -> float:
        """Load torque of a sensor source (N·m, raw direction), 0 for plain signals."""
        return self.source_at(self._now() if t is None else t).load_torque(t)


# -- machine file -----------------------------------------------------------------
def _volts(table: Mapping[str, Any], key: str, default: float | None = None) -> float:
    unit = str(table.get("unit", "V")).lower()
    if unit not in ("v", "volts", "counts"):
        raise ValueError(f"[axis.analog] unit must be 'V' or 'counts', not {unit!r}")
    if key not in table:
        if default is None:
            raise ValueError(f"[axis.analog] needs {key!r}")
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"[axis.analog] {key} must be a number")
    return counts_to_volts(value) if unit == "counts" else float(value)


def _number(table: Mapping[str, Any], key: str, default: float,
            lo: float = -1e9, hi: float = 1e9) -> float:
    """A finite number within ``lo..hi`` (times in seconds, phases in degrees: beyond
    1e9 the sampling arithmetic loses every digit)."""
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"[axis.analog] {key} must be a finite number")
    if not lo <= value <= hi:
        raise ValueError(f"[axis.analog] {key} must be {lo:g}..{hi:g}, not {value!r}")
    return float(value)


def _read_csv(path: Path, unit_counts: bool) -> list[tuple[float, float]]:
    rows: list[tuple[float, float]] = []
    with path.open(newline="", encoding="utf-8") as fh:
        for line_no, row in enumerate(csv.reader(fh), 1):
            if not row or row[0].strip().startswith("#"):
                continue
            try:
                t, v = float(row[0]), float(row[1])
            except (ValueError, IndexError):
                if not rows and line_no == 1:
                    continue            # a header line
                raise ValueError(f"{path}:{line_no}: expected 'time_s,value'") from None
            rows.append((t, counts_to_volts(v) if unit_counts else v))
    return rows


#: The keys of each kind of ``[axis.analog]`` (docs/machine-file.md); others are errors.
_ANALOG_KEYS: dict[str, frozenset[str]] = {
    "constant": frozenset({"kind", "unit", "value"}),
    "ramp": frozenset({"kind", "unit", "from", "to", "start", "duration"}),
    "sine": frozenset({"kind", "unit", "offset", "amplitude", "frequency", "phase"}),
    "csv": frozenset({"kind", "unit", "file", "interpolate", "repeat"}),
    "torque-sensor": frozenset({"kind", "offset", "volts_per_nm", "stiffness", "contact",
                                "direction"}),
}


def _known_keys(table: Mapping[str, Any], known: frozenset[str], what: str) -> None:
    """A misspelt key is an error, not a silent default (docs/machine-file.md)."""
    unknown = sorted(str(k) for k in table if k not in known)
    if unknown:
        raise ValueError(f"{what}: unknown key {unknown[0]!r} (known: "
                         f"{', '.join(sorted(known))})")


def source_from_config(table: Mapping[str, Any], *, base_dir: Path | str | None = None
                       ) -> AnalogSource:
    """An :class:`AnalogSource` from a machine file's ``[axis.analog]`` table.

    ``kind`` is ``constant`` (``value``), ``ramp`` (``from``, ``to``, ``start`` s,
    ``duration`` s), ``sine`` (``offset``, ``amplitude``, ``frequency`` Hz,
    ``phase`` deg), ``csv`` (``file``, ``interpolate`` linear|step, ``repeat``) or
    ``torque-sensor`` (``offset`` V, ``volts_per_nm``, ``stiffness`` N·m/pulse,
    ``contact`` pulses, ``direction`` ±1).  Values are volts unless ``unit =
    "counts"``.  Raises ``ValueError`` with the reason for a bad table.
    """
    kind = str(table.get("kind", "constant")).lower()
    if kind in _ANALOG_KEYS:
        _known_keys(table, _ANALOG_KEYS[kind], f"[axis.analog] kind {kind!r}")
    if kind == "constant":
        return Constant(_volts(table, "value", 0.0))
    if kind == "ramp":
        duration = _number(table, "duration", 1.0)
        if duration <= 0:
            raise ValueError("[axis.analog] ramp duration must be > 0")
        return Ramp(_volts(table, "from"), _volts(table, "to"),
                    round(_number(table, "start", 0.0) * NS_PER_S), round(duration * NS_PER_S))
    if kind == "sine":
        return Sine(_volts(table, "offset", 2.5), _volts(table, "amplitude", 1.0),
                    _number(table, "frequency", 1.0, 0.0, 1e6), _number(table, "phase", 0.0))
    if kind == "csv":
        if "file" not in table:
            raise ValueError("[axis.analog] csv needs 'file'")
        path = Path(str(table["file"]))
        if not path.is_absolute() and base_dir is not None:
            path = Path(base_dir) / path
        counts = str(table.get("unit", "V")).lower() == "counts"
        try:
            points = _read_csv(path, counts)
        except OSError as exc:
            raise ValueError(f"[axis.analog] cannot read {path}: {exc.strerror or exc}") from exc
        return Table(points, interpolate=str(table.get("interpolate", "linear")),
                     repeat=bool(table.get("repeat", False)))
    if kind == "torque-sensor":
        return TorqueSensor(offset=_number(table, "offset", 2.5),
                            volts_per_nm=_number(table, "volts_per_nm", 5.0),
                            stiffness=_number(table, "stiffness", 1e-4),
                            contact=_number(table, "contact", 0.0),
                            direction=int(_number(table, "direction", 1)))
    raise ValueError(f"[axis.analog] kind must be constant, ramp, sine, csv or "
                     f"torque-sensor, not {kind!r}")
