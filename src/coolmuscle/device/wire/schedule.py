"""Wire faults in virtual time: each one's window, its own generator, and the record.

:func:`wire_fault` checks one fault against the vocabulary (:mod:`.vocabulary`) into a
:class:`WireFault`; :class:`WireFaults` (one per device, the chain's ``wire_faults``)
installs it: the fault is *live* from ``at`` to ``until`` (kernel events), a door asks
:meth:`WireFaults.hit` for each message it sends and :meth:`WireFaults.lasting` for the
state of a lasting fault, and everything a fault does is told to the listeners
(:class:`WireRecord`: the chain turns them into ``wire`` events, the transcript and
the trace show them).

Deterministic: which messages a fault hits depends only on the messages a door asks
about and on the fault's own generator (SplitMix64, seeded by ``seed``, by default the
fault's number), never on the wall clock or the ``random`` module, so the same run
gives the same bytes.  ``every = N`` hits the N-th, 2N-th ... message of the window;
``probability = p`` each message with probability p; neither: every message;
``count`` stops after that many hits.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

from ...sim.kernel import PRIO_IO, Kernel, Timer, seconds
from .vocabulary import FaultKind, Value, finite, kind_of

__all__ = ["WireFault", "ActiveFault", "WireRecord", "WireFaults", "Generator",
           "wire_fault", "SCHEDULE_KEYS", "MAX_TIME_S"]

#: The keys of a fault that schedule it; every other key is a parameter of its kind.
SCHEDULE_KEYS = ("door", "kind", "at", "until", "every", "probability", "seed", "count",
                 "motor")
#: Faults happen within this many seconds (as a machine file's ``at``).
MAX_TIME_S = 1e9
_MASK64 = (1 << 64) - 1


@dataclass(frozen=True)
class WireFault:
    """One wire fault, checked: what, where, when and how often (seconds are counted
    from the instant it is installed)."""

    door: str
    kind: str
    params: Mapping[str, Value] = field(default_factory=dict)
    at: float = 0.0
    until: float | None = None
    every: int | None = None
    probability: float | None = None
    seed: int | None = None
    count: int | None = None
    motor: int | None = None

    @property
    def spec(self) -> FaultKind:
        return kind_of(self.door, self.kind)

    def describe(self) -> dict[str, object]:
        """JSON-ready (the web page's list of faults)."""
        out: dict[str, object] = {"door": self.door, "kind": self.kind, "at": self.at}
        for key in ("until", "every", "probability", "seed", "count", "motor"):
            value = getattr(self, key)
            if value is not None:
                out[key] = value
        out["params"] = dict(self.params)
        return out


def _number(value: object, name: str, where: str, lo: float, hi: float) -> float:
    # compared before any float(): an integer of 400 digits is out of range, not an
    # OverflowError
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not lo <= value <= hi or not finite(value):
        raise ValueError(f"{where}: {name} must be a number {lo:g}..{hi:g}, not {value!r}")
    return float(value)


def _whole(value: object, name: str, where: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{where}: {name} must be an integer {lo}..{hi}, not {value!r}")
    return value


def wire_fault(door: object, kind: object, schedule: Mapping[str, object] | None = None,
               params: Mapping[str, object] | None = None,
               where: str = "wire fault") -> WireFault:
    """Check one fault into a :class:`WireFault` (``ValueError`` naming ``where`` and the
    key): ``schedule`` holds ``at``, ``until``, ``every``, ``probability``, ``seed``,
    ``count``, ``motor`` (each optional), ``params`` the kind's parameters."""
    spec = kind_of(door, kind)
    where = f"{where} ({spec.door} {spec.name})"
    plan = dict(schedule or {})
    unknown = sorted(set(plan) - set(SCHEDULE_KEYS[2:]))
    if unknown:
        raise ValueError(f"{where}: {unknown[0]!r} is no schedule key "
                         f"({', '.join(SCHEDULE_KEYS[2:])})")
    every, probability, count = plan.get("every"), plan.get("probability"), plan.get("count")
    start = _number(plan.get("at", 0.0), "at", where, 0.0, MAX_TIME_S)
    until = plan.get("until")
    end = None if until is None else _number(until, "until", where, start, MAX_TIME_S)
    if spec.lasting and any(v is not None for v in (every, probability, count)):
        raise ValueError(f"{where}: a lasting fault holds from at to until; every, "
                         "probability and count choose messages of the others")
    if every is not None and probability is not None:
        raise ValueError(f"{where}: every or probability, not both")
    seed, motor = plan.get("seed"), plan.get("motor")
    if spec.motor == "required":
        checked_motor: int | None = _whole(motor, "motor", where, 1, 15)
    elif motor is not None:
        raise ValueError(f"{where}: this fault names no motor")
    else:
        checked_motor = None
    return WireFault(
        spec.door, spec.name, spec.check_params(params or {}, where), start, end,
        None if every is None else _whole(every, "every", where, 1, 2**31),
        None if probability is None else _number(probability, "probability", where, 0, 1),
        None if seed is None else _whole(seed, "seed", where, 0, _MASK64),
        None if count is None else _whole(count, "count", where, 1, 2**31), checked_motor)


class Generator:
    """SplitMix64: a small generator whose numbers are the same on every platform and
    Python version (a fault's choices must repeat bit for bit)."""

    __slots__ = ("_state",)

    def __init__(self, seed: int) -> None:
        self._state = seed & _MASK64

    def next64(self) -> int:
        self._state = (self._state + 0x9E3779B97F4A7C15) & _MASK64
        z = self._state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
        return z ^ (z >> 31)

    def uniform(self) -> float:
        """A number in [0, 1)."""
        return (self.next64() >> 11) / float(1 << 53)

    def below(self, n: int) -> int:
        """An integer in [0, n) (``n`` > 0)."""
        return self.next64() % n


@dataclass(frozen=True)
class WireRecord:
    """Something a wire fault did, at virtual time ``time`` (ns)."""

    time: int
    fault: int
    door: str
    kind: str
    motor: int | None
    text: str

    def line(self) -> str:
        """``wire fault 2 host-line drop: ...`` (the event's and the transcript's text)."""
        return f"wire fault {self.fault} {self.door} {self.kind}: {self.text}"


class ActiveFault:
    """One installed fault: its window in kernel time, its generator and its counts."""

    def __init__(self, number: int, fault: WireFault, start: int, end: int | None) -> None:
        self.id = number
        self.fault = fault
        self.door, self.kind, self.motor = fault.door, fault.kind, fault.motor
        self.params = fault.params
        self.lasting = fault.spec.lasting
        self.start, self.end = start, end
        self.rng = Generator(number if fault.seed is None else fault.seed)
        self.seen = 0
        self.hits = 0
        self.live = False
        self.over = False
        self.timers: list[Timer] = []

    def decide(self) -> bool:
        """Whether this message is hit (counts it; the generator draws only with a
        probability)."""
        self.seen += 1
        fault = self.fault
        if fault.count is not None and self.hits >= fault.count:
            return False
        if fault.every is not None:
            hit = self.seen % fault.every == 0
        elif fault.probability is not None:
            hit = self.rng.uniform() < fault.probability
        else:
            hit = True
        if hit:
            self.hits += 1
        return hit

    @property
    def spent(self) -> bool:
        return self.fault.count is not None and self.hits >= self.fault.count

    def describe(self) -> dict[str, object]:
        return {"id": self.id, **self.fault.describe(), "live": self.live,
                "over": self.over, "hits": self.hits, "seen": self.seen}


Watcher = Callable[[ActiveFault, bool], None]
Listener = Callable[[WireRecord], None]


class WireFaults:
    """The wire faults of one device (see the module docstring)."""

    def __init__(self, kernel: Kernel) -> None:
        self.kernel = kernel
        #: Every fault installed and not over or cleared, in order.
        self.faults: list[ActiveFault] = []
        self._live: dict[str, list[ActiveFault]] = {}
        self._watchers: dict[str, list[Watcher]] = {}
        self._every: dict[str, list[Watcher]] = {}
        self._listeners: list[Listener] = []
        self._number = 0
        self.records = 0

    # -- installing ------------------------------------------------------------------------
    def add(self, fault: WireFault) -> ActiveFault:
        """Install ``fault``: live from ``at`` seconds from now until ``until``."""
        now = self.kernel.now
        self._number += 1
        end = None if fault.until is None else now + seconds(fault.until)
        active = ActiveFault(self._number, fault, now + seconds(fault.at), end)
        self.faults.append(active)
        if active.start <= now:
            self._begin(active)
        else:
            active.timers.append(self.kernel.schedule_at(
                active.start, lambda: self._begin(active), priority=PRIO_IO,
                name="wire fault starts"))
        if end is not None:
            active.timers.append(self.kernel.schedule_at(
                end, lambda: self._finish(active), priority=PRIO_IO, name="wire fault ends"))
        return active

    def clear(self, number: int | None = None, door: str | None = None) -> int:
        """End and forget faults: the one numbered ``number``, those of ``door``, or
        all; returns how many."""
        gone = [f for f in self.faults if (number is None or f.id == number)
                and (door is None or f.door == door)]
        for fault in gone:
            for timer in fault.timers:
                timer.cancel()
            self._finish(fault)
        return len(gone)

    def _begin(self, fault: ActiveFault) -> None:
        if fault.over or fault.live:
            return
        fault.live = True
        self._live.setdefault(fault.door, []).append(fault)
        if fault.lasting:
            self.record(fault, "begins")
            self._tell(fault, True)
        self._tell_every(fault, True)

    def _finish(self, fault: ActiveFault) -> None:
        if fault.over:
            return
        fault.over = True
        fault.timers.clear()
        if fault in self.faults:          # what is over is forgotten: a storm stays small
            self.faults.remove(fault)
        if not fault.live:
            return
        fault.live = False
        live = self._live.get(fault.door, [])
        if fault in live:
            live.remove(fault)
        if not live:
            self._live.pop(fault.door, None)
        if fault.lasting:
            self.record(fault, "ends")
            self._tell(fault, False)
        self._tell_every(fault, False)

    # -- what the doors ask ------------------------------------------------------------------
    def live(self, door: str) -> bool:
        """Whether ``door`` has a fault within its window now (cheap: the doors' fast
        path asks this first)."""
        return door in self._live

    def hit(self, door: str, kinds: Iterable[str] | None = None, motor: int | None = None,
            where: Callable[[ActiveFault], bool] | None = None) -> ActiveFault | None:
        """The first live per-message fault of ``door`` (of ``kinds``, for ``motor``, that
        ``where`` accepts) that hits the message being sent now, or ``None``.  Each
        fault asked counts the message."""
        for fault in list(self._live.get(door, ())):
            if fault.lasting or (kinds is not None and fault.kind not in kinds):
                continue
            if fault.motor is not None and motor is not None and fault.motor != motor:
                continue
            if where is not None and not where(fault):
                continue
            if fault.decide():
                if fault.spent:
                    self._finish(fault)
                return fault
        return None

    def lasting(self, door: str, kind: str, motor: int | None = None) -> ActiveFault | None:
        """The live lasting fault ``kind`` of ``door`` (for ``motor``), or ``None``."""
        for fault in self._live.get(door, ()):
            if fault.kind == kind and fault.lasting and (motor is None or fault.motor == motor):
                return fault
        return None

    def live_faults(self, door: str) -> list[ActiveFault]:
        """The live faults of ``door`` now, in the order they were installed."""
        return list(self._live.get(door, ()))

    # -- telling -------------------------------------------------------------------------------
    def watch(self, door: str, watcher: Watcher, *, every_kind: bool = False
              ) -> Callable[[], None]:
        """Call ``watcher(fault, on)`` when a lasting fault of ``door`` begins or ends;
        ``every_kind``: when any fault of ``door`` enters or leaves its window (a door
        that hands the live faults to another thread republishes them then)."""
        watchers = self._every if every_kind else self._watchers
        watchers.setdefault(door, []).append(watcher)

        def remove() -> None:
            found = watchers.get(door, [])
            if watcher in found:
                found.remove(watcher)
        return remove

    def listen(self, listener: Listener) -> Callable[[], None]:
        """Call ``listener(record)`` for everything a fault does."""
        self._listeners.append(listener)
        return lambda: self._listeners.remove(listener) if listener in self._listeners \
            else None

    def _tell(self, fault: ActiveFault, on: bool) -> None:
        for watcher in list(self._watchers.get(fault.door, ())):
            watcher(fault, on)

    def _tell_every(self, fault: ActiveFault, on: bool) -> None:
        for watcher in list(self._every.get(fault.door, ())):
            watcher(fault, on)

    def record(self, fault: ActiveFault, text: str) -> WireRecord:
        """Tell the listeners what ``fault`` did now (the door that acted says what)."""
        entry = WireRecord(self.kernel.now, fault.id, fault.door, fault.kind, fault.motor, text)
        self.records += 1
        for listener in list(self._listeners):
            listener(entry)
        return entry

    def describe(self) -> list[dict[str, object]]:
        """Every installed fault, JSON-ready (the web page)."""
        return [f.describe() for f in self.faults]
