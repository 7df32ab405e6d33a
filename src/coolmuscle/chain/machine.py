"""Machine files (TOML): what each motor drives — load, stoppers, sensors, scheduled
inputs and faults (docs/machine-file.md has the full schema and examples/*.toml).

:func:`parse_machine` / :func:`load_machine` read and check a file into a
:class:`Machine` (every mistake is a :class:`MachineFileError` naming the key);
:func:`apply_machine` installs it on a chain: plant and thermal data, the shaft's start
position, stoppers, position sensors wired to inputs (their edges are solved from the
actual position, :mod:`coolmuscle.motor.supervision.sensors`), K parameters, and kernel events for
the input and fault schedules.  The ``[axis.analog]`` and ``[axis.encoder]`` tables are
handed to ``coolmuscle.motor.signals.analog.source_from_config`` and
``coolmuscle.motor.signals.encoder.gearing_from_config`` (imported when used).

A machine built on an EtherCAT segment (several bridges, each with its own chain of
motors ID1-ID4) names its bridges in ``[ethercat] bridges`` and each ``[[axis]]`` its
bridge (``bridge = 2``); :meth:`Machine.for_bridge` is the part of one bridge's chain
and :func:`apply_machine` installs the tables of bridge 1 (every table's default).
The bridge codes are checked by the EtherCAT front end that uses them.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from ..device.wire.schedule import SCHEDULE_KEYS, WireFault, wire_fault
from ..device.wire.vocabulary import MAX_BRIDGES
from ..errors import CoolMuscleError
from ..motor.signals.analog import source_from_config
from ..motor.signals.encoder import gearing_from_config
from ..motor.supervision.sensors import PositionSensor
from ..sim.kernel import Kernel, seconds

if TYPE_CHECKING:
    from ..motor.motor import Motor


class MachineHost(Protocol):
    """What installing a machine needs of the chain (implemented by ``Chain``)."""

    kernel: Kernel

    def motor(self, motor_id: int) -> Motor | None: ...

    def set_input(self, motor: int, number: int, on: bool) -> None: ...

    def inject_fault(self, motor: int, fault: str, **params: object) -> None: ...

    def add_wire_fault(self, fault: WireFault) -> int: ...


class MachineFileError(CoolMuscleError, ValueError):
    """A machine file that cannot be read or does not fit the schema."""


#: Machine-file keys of ``[axis.load]`` and ``[axis.drive]`` -> the Plant attributes they set.
LOAD_KEYS = {"inertia": "load_inertia", "friction": "coulomb_friction", "torque": "load_torque"}
DRIVE_KEYS = {"rotor_inertia": "rotor_inertia", "rated_torque": "rated_torque",
              "peak_torque": "peak_torque", "max_speed": "max_speed", "kp": "kp"}
_THERMAL = {"idle": "idle", "rise": "rise_at_rated", "time_constant": "time_constant",
            "alarm": "alarm"}
#: What each physical quantity may be (docs/machine-file.md): wide enough for any
#: machine a Cool Muscle can drive, narrow enough that the load model's arithmetic
#: stays finite (a 1e308 N·m load once made every position NaN).
BOUNDS: dict[str, tuple[float, float]] = {
    "inertia": (0.0, 10.0), "friction": (0.0, 1000.0), "torque": (-1000.0, 1000.0),
    "rotor_inertia": (1e-9, 10.0), "rated_torque": (1e-4, 1000.0),
    "peak_torque": (1.0, 10000.0), "max_speed": (1.0, 100000.0), "kp": (1e-3, math.inf),
    "idle": (-40.0, 200.0), "rise": (0.0, 500.0), "time_constant": (0.001, 1e7),
    "alarm": (-40.0, 500.0)}
#: Scheduled inputs and faults happen within this many seconds (as ``run --until``).
MAX_TIME_S = 1e9
#: A machine position (pulses) far beyond any travel, still exact in a float.
MAX_POSITION = 1e12
_NAMED_SENSORS = ("origin_sensor", "cw_limit", "ccw_limit")
_AXIS_KEYS = frozenset({"motor", "bridge", "ppr", "start", "params", "load", "drive", "thermal",
                        "stoppers", "sensor", "input", "fault", "analog", "encoder",
                        *_NAMED_SENSORS})
#: Lasting faults an ``until`` can clear, and the parameters their clearing needs.
_CLEARABLE = {"overload": (), "supply_voltage": (), "stuck_input": ("input",),
              "broken_cable": ("cable",)}


@dataclass
class SensorSpec:
    name: str
    input: int
    lo: float
    hi: float
    normally_closed: bool = False


@dataclass
class ScheduledInput:
    at: float
    input: int
    on: bool


@dataclass
class ScheduledFault:
    at: float
    fault: str
    params: dict[str, object]
    until: float | None = None


@dataclass
class AxisSpec:
    """One ``[[axis]]`` table."""

    motor: int
    #: The EtherCAT bridge whose chain the motor is on (1 = the first; ``[ethercat]``).
    bridge: int = 1
    ppr: int = 1000
    start: float = 0.0
    params: dict[int, int] = field(default_factory=dict)
    load: dict[str, float] = field(default_factory=dict)
    motor_data: dict[str, float] = field(default_factory=dict)
    z_phase: float | None = None
    thermal: dict[str, float] = field(default_factory=dict)
    stoppers: tuple[float, float] = (-math.inf, math.inf)
    sensors: list[SensorSpec] = field(default_factory=list)
    inputs: list[ScheduledInput] = field(default_factory=list)
    faults: list[ScheduledFault] = field(default_factory=list)
    analog: dict[str, Any] | None = None
    encoder: dict[str, Any] | None = None


@dataclass
class Machine:
    axes: list[AxisSpec]
    source: str = "<machine>"
    #: ``[ethercat] bridges``: the variants of the bridges in line order (empty: none).
    bridges: tuple[str, ...] = ()
    #: ``[[wire.fault]]``: communication faults (docs/wire-faults.md)
    wire: list[WireFault] = field(default_factory=list)

    def for_bridge(self, bridge: int) -> Machine:
        """The tables of bridge ``bridge``'s chain, as a machine of one chain.  The wire
        faults go with bridge 1: its device holds the segment's faults (the ``ethercat``
        door names the bridge it hits) and its host line, chain and Modbus doors."""
        return Machine([replace(a, bridge=1) for a in self.axes if a.bridge == bridge],
                       self.source if bridge == 1 else f"{self.source} (bridge {bridge})",
                       self.bridges, list(self.wire) if bridge == 1 else [])


# -- reading ------------------------------------------------------------------------
def load_machine(path: str | Path) -> Machine:
    """Read and check a machine file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise MachineFileError(f"cannot read machine file {path}: {exc.strerror or exc}") \
            from None
    except UnicodeDecodeError as exc:
        raise MachineFileError(f"{path}: not UTF-8 text (byte {exc.start}): a machine file "
                               "is TOML") from None
    return parse_machine(text, str(path))


def parse_machine(text: str, source: str = "<machine>") -> Machine:
    """Check machine-file text (TOML) against the schema (docs/machine-file.md)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MachineFileError(f"{source}: not valid TOML: {exc}") from None
    except RecursionError:
        raise MachineFileError(f"{source}: arrays or tables nested too deeply") from None
    unknown = set(data) - {"axis", "name", "description", "ethercat", "wire"}
    if unknown:
        raise MachineFileError(f"{source}: unknown top-level key {sorted(unknown)[0]!r}")
    bridges = _bridges(data.get("ethercat", {}), source)
    tables = data.get("axis", [])
    if isinstance(tables, dict):
        tables = [tables]
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise MachineFileError(f"{source}: 'axis' must be [[axis]] tables")
    try:
        axes = [_axis(t, i, source) for i, t in enumerate(tables)]
    except RecursionError:
        raise MachineFileError(f"{source}: arrays or tables nested too deeply") from None
    ids = [(a.bridge, a.motor) for a in axes]
    if len(set(ids)) != len(ids):
        raise MachineFileError(f"{source}: two [[axis]] tables for the same motor")
    for a in axes:
        if a.bridge > max(1, len(bridges)):
            raise MachineFileError(f"{source}: axis motor={a.motor} bridge={a.bridge}: "
                                   f"[ethercat] bridges names {len(bridges)} bridge(s)")
    return Machine(axes, source, bridges, _wire(data.get("wire", {}), source))


def _bridges(value: object, source: str) -> tuple[str, ...]:
    """``[ethercat] bridges = ["EB02", "EB12"]``: the segment's bridges in line order."""
    where = f"{source}: ethercat"
    if not isinstance(value, dict):
        raise MachineFileError(f"{where}: must be a table")
    unknown = set(value) - {"bridges"}
    if unknown:
        raise MachineFileError(f"{where}: unknown key {sorted(unknown)[0]!r} (known: bridges)")
    bridges = value.get("bridges", [])
    if not isinstance(bridges, list) or not all(isinstance(b, str) and b for b in bridges) \
            or len(bridges) > MAX_BRIDGES:
        raise MachineFileError(f"{where}.bridges: expected a list of at most {MAX_BRIDGES} "
                               'bridge names, e.g. ["EB02", "EB12"]')
    return tuple(b.upper() for b in bridges)


def _wire(value: object, source: str) -> list[WireFault]:
    """``[[wire.fault]]``: each checked against the wire-fault vocabulary."""
    if not isinstance(value, dict):
        raise MachineFileError(f"{source}: 'wire' must be a table holding [[wire.fault]]")
    unknown = set(value) - {"fault"}
    if unknown:
        raise MachineFileError(f"{source}: wire: unknown key {sorted(unknown)[0]!r} (fault)")
    faults = []
    for i, table in enumerate(_list(value.get("fault", []), f"{source}: wire.fault")):
        where = f"{source}: wire.fault[{i + 1}]"
        schedule = {k: v for k, v in table.items() if k in SCHEDULE_KEYS[2:]}
        params = {k: v for k, v in table.items() if k not in SCHEDULE_KEYS}
        try:
            faults.append(wire_fault(table.get("door"), table.get("kind"), schedule,
                                     params, where))
        except ValueError as exc:
            message = str(exc)
            raise MachineFileError(message if message.startswith(where)
                                   else f"{where}: {message}") from None
    return faults


def _axis(t: dict[str, Any], index: int, source: str) -> AxisSpec:
    where = f"{source}: axis {index + 1}"
    unknown = set(t) - _AXIS_KEYS
    if unknown:
        raise MachineFileError(f"{where}: unknown key {sorted(unknown)[0]!r}")
    spec = AxisSpec(motor=_int(t.get("motor", index + 1), f"{where}.motor", 1, 15),
                    bridge=_int(t.get("bridge", 1), f"{where}.bridge", 1, MAX_BRIDGES))
    where = f"{source}: axis motor={spec.motor}" + (f" bridge={spec.bridge}"
                                                    if spec.bridge > 1 else "")
    spec.ppr = _int(t.get("ppr", 1000), f"{where}.ppr", 1, 10_000_000)
    spec.start = _num(t.get("start", 0.0), f"{where}.start", -MAX_POSITION, MAX_POSITION)
    spec.params = _params(t.get("params", {}), f"{where}.params")
    spec.load = _table(t.get("load", {}), LOAD_KEYS, f"{where}.load")
    drive = t.get("drive", {})
    if not isinstance(drive, dict):
        raise MachineFileError(f"{where}.drive: must be a table")
    drive = dict(drive)
    if "z_phase" in drive:
        spec.z_phase = _num(drive.pop("z_phase"), f"{where}.drive.z_phase")
    spec.motor_data = _table(drive, DRIVE_KEYS, f"{where}.drive")
    spec.thermal = _table(t.get("thermal", {}), _THERMAL, f"{where}.thermal")
    spec.stoppers = _stoppers(t.get("stoppers", {}), f"{where}.stoppers")
    for name in _NAMED_SENSORS:
        if name in t:
            spec.sensors.append(_sensor(t[name], name, f"{where}.{name}"))
    for i, s in enumerate(_list(t.get("sensor", []), f"{where}.sensor")):
        spec.sensors.append(_sensor(s, str(s.get("name", f"sensor {i + 1}")),
                                    f"{where}.sensor[{i + 1}]"))
    spec.inputs = [_scheduled_input(s, f"{where}.input[{i + 1}]")
                   for i, s in enumerate(_list(t.get("input", []), f"{where}.input"))]
    spec.faults = [_scheduled_fault(s, f"{where}.fault[{i + 1}]")
                   for i, s in enumerate(_list(t.get("fault", []), f"{where}.fault"))]
    for key in ("analog", "encoder"):
        if key in t:
            if not isinstance(t[key], dict):
                raise MachineFileError(f"{where}.{key}: must be a table")
            setattr(spec, key, dict(t[key]))
    return spec


def _num(value: object, where: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
        raise MachineFileError(f"{where}: expected a number, got {value!r}")
    if not lo <= value <= hi:
        raise MachineFileError(f"{where}: {value!r} is outside {lo:g}..{hi:g}")
    return float(value)


def _int(value: object, where: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise MachineFileError(f"{where}: expected an integer, got {value!r}")
    if not lo <= value <= hi:
        raise MachineFileError(f"{where}: {value} is outside {lo}..{hi}")
    return value


def _list(value: object, where: str) -> list[dict[str, Any]]:
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise MachineFileError(f"{where}: expected [[...]] tables")
    return value


def _table(value: object, keys: dict[str, str], where: str) -> dict[str, float]:
    if not isinstance(value, dict):
        raise MachineFileError(f"{where}: must be a table")
    unknown = set(value) - set(keys)
    if unknown:
        raise MachineFileError(f"{where}: unknown key {sorted(unknown)[0]!r} "
                               f"(known: {', '.join(keys)})")
    return {keys[k]: _num(v, f"{where}.{k}", *BOUNDS.get(k, (-math.inf, math.inf)))
            for k, v in value.items()}


def _params(value: object, where: str) -> dict[int, int]:
    if not isinstance(value, dict):
        raise MachineFileError(f"{where}: must be a table like {{ K27 = 62 }}")
    out: dict[int, int] = {}
    for key, v in value.items():
        name = str(key).upper()
        if not (name.startswith("K") and name[1:].isdigit()):
            raise MachineFileError(f"{where}: {key!r} is not a K parameter")
        out[int(name[1:])] = _int(v, f"{where}.{key}", -1_000_000_000, 1_000_000_000)
    return out


def _stoppers(value: object, where: str) -> tuple[float, float]:
    if not isinstance(value, dict):
        raise MachineFileError(f"{where}: must be a table")
    unknown = set(value) - {"ccw", "cw"}
    if unknown:
        raise MachineFileError(f"{where}: unknown key {sorted(unknown)[0]!r} (ccw, cw)")
    lo = _num(value.get("ccw", -math.inf), f"{where}.ccw")
    hi = _num(value.get("cw", math.inf), f"{where}.cw")
    if not lo < hi:
        raise MachineFileError(f"{where}: ccw must be below cw")
    return lo, hi


def _sensor(value: object, name: str, where: str) -> SensorSpec:
    if not isinstance(value, dict):
        raise MachineFileError(f"{where}: must be a table")
    unknown = set(value) - {"input", "on", "normally_closed", "name"}
    if unknown:
        raise MachineFileError(f"{where}: unknown key {sorted(unknown)[0]!r}")
    rng = value.get("on")
    if not isinstance(rng, list) or len(rng) != 2:
        raise MachineFileError(f"{where}.on: expected [from, to] (machine pulses)")
    lo, hi = (_num(x, f"{where}.on") for x in rng)
    if lo > hi:
        raise MachineFileError(f"{where}.on: from must not exceed to")
    return SensorSpec(name, _int(value.get("input"), f"{where}.input", 1, 6), lo, hi,
                      bool(value.get("normally_closed", False)))


def _scheduled_input(value: dict[str, Any], where: str) -> ScheduledInput:
    unknown = set(value) - {"at", "input", "on"}
    if unknown:
        raise MachineFileError(f"{where}: unknown key {sorted(unknown)[0]!r}")
    on = value.get("on")
    if not isinstance(on, bool):
        raise MachineFileError(f"{where}.on: expected true or false")
    return ScheduledInput(_num(value.get("at"), f"{where}.at", 0.0, MAX_TIME_S),
                          _int(value.get("input"), f"{where}.input", 1, 6), on)


def _scheduled_fault(value: dict[str, Any], where: str) -> ScheduledFault:
    params = {k: v for k, v in value.items() if k not in ("at", "fault", "until")}
    fault = value.get("fault")
    if not isinstance(fault, str):
        raise MachineFileError(f"{where}.fault: expected a fault name")
    until = value.get("until")
    at = _num(value.get("at"), f"{where}.at", 0.0, MAX_TIME_S)
    if until is not None:
        until = _num(until, f"{where}.until", at, MAX_TIME_S)
        if fault not in _CLEARABLE:
            raise MachineFileError(f"{where}.until: {fault!r} is not a lasting fault")
    return ScheduledFault(at, fault, params, until)


# -- installing -----------------------------------------------------------------------
def apply_machine(machine: Machine, chain: MachineHost) -> None:
    """Install ``machine`` on ``chain`` now (MachineFileError if it does not fit): the
    ``[[axis]]`` tables of bridge 1 (:meth:`Machine.for_bridge` gives another's)."""
    for spec in machine.axes:
        if spec.bridge != 1:
            continue
        motor = chain.motor(spec.motor)
        if motor is None:
            raise MachineFileError(f"{machine.source}: no motor ID{spec.motor} on the chain")
        try:
            _install(spec, motor, chain)
        except (ValueError, LookupError) as exc:
            if isinstance(exc, MachineFileError):
                raise
            raise MachineFileError(f"{machine.source}: motor {spec.motor}: {exc}") from None
    for i, fault in enumerate(machine.wire):
        try:
            chain.add_wire_fault(fault)
        except (ValueError, LookupError) as exc:
            raise MachineFileError(f"{machine.source}: wire.fault[{i + 1}] ({fault.door} "
                                   f"{fault.kind}): {exc}") from None


def _install(spec: AxisSpec, motor: Motor, chain: MachineHost) -> None:
    for k, value in spec.params.items():
        motor.params.set(k, value)
    for attr, amount in {**spec.load, **spec.motor_data}.items():
        setattr(motor.plant, attr, amount)
    for attr, amount in spec.thermal.items():
        setattr(motor.thermal, attr, amount)
    motor.thermal.reset(None, chain.kernel.now)
    geo = motor.geometry
    geo.ppr = spec.ppr
    geo.stopper_ccw, geo.stopper_cw = spec.stoppers
    if spec.z_phase is not None:
        geo.z_phase = spec.z_phase
    motor.axis.place(spec.start * motor.resolution.pulses_per_rev / spec.ppr)
    for s in spec.sensors:
        if s.input > motor.io.input_count:
            raise MachineFileError(f"sensor {s.name!r}: input {s.input} "
                                   f"(this firmware has 1..{motor.io.input_count})")
        sensor = PositionSensor(s.name, s.input, s.lo, s.hi, spec.ppr, s.normally_closed)
        geo.sensors.append(sensor)
        sensor.attach(motor)
    _schedule(spec, motor, chain)
    if spec.analog is not None:        # [axis.analog] / [axis.encoder]: their owners parse them
        motor.analog_config = source_from_config(spec.analog)
    if spec.encoder is not None:
        motor.encoder_config = gearing_from_config(spec.encoder)


def _schedule(spec: AxisSpec, motor: Motor, chain: MachineHost) -> None:
    kernel, now, mid = chain.kernel, chain.kernel.now, motor.id
    for item in spec.inputs:
        kernel.schedule_at(now + seconds(item.at),
                           partial(chain.set_input, mid, item.input, item.on),
                           name="machine input")
    for f in spec.faults:
        motor.faults.check(f.fault, f.params)
        kernel.schedule_at(now + seconds(f.at),
                           partial(chain.inject_fault, mid, f.fault, **f.params),
                           name="machine fault")
        if f.until is not None:
            keep = {k: f.params[k] for k in _CLEARABLE[f.fault] if k in f.params}
            kernel.schedule_at(now + seconds(f.until),
                               partial(chain.inject_fault, mid, f.fault, clear=True, **keep),
                               name="machine fault cleared")
