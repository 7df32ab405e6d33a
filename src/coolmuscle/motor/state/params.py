"""K parameters: the spec of one parameter and the per-motor parameter table.

This module owns how a K value is validated (cml-users-guide.txt ch. 3 and table
6.1), how a write is applied or refused, who is told about a change, and the
``?90`` listing (6.6).  The spec tables themselves differ per firmware and live in
:mod:`coolmuscle.motor.state.firmware`.

Ch. 3: "Each parameter has individual setting range.  The value out of the range
will not be reflected.  The changed value is saved automatically."  So
:meth:`ParamTable.set` either applies a value completely or raises
:class:`~coolmuscle.errors.OutOfRangeError` and changes nothing; persistence is
the motor's job, through :meth:`ParamTable.on_change`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterator, Literal, Mapping

from ...errors import OutOfRangeError

if TYPE_CHECKING:
    from .firmware import Firmware

#: How a value is validated.  ``range``: min..max.  ``digits``: digit by digit,
#: each decimal digit (ones digit first) in its own range (table 6.1 "Each digit
#: must be set individually").  ``choice``: one of ``choices``.  ``reserved``: a
#: number table 6.1 does not define; it reads a fixed value and accepts only it.
ParamKind = Literal["range", "digits", "choice", "reserved"]

#: The K numbers ``?90`` lists and ``K##.n=`` can address (6.6 ?90: "K20 ~K89").
FIRST_K = 20
LAST_K = 89

#: ``?90`` prints this many parameters per line (6.6 ?90).
PER_LINE = 4

ChangeListener = Callable[[int, int, int], None]


class NoSuchParameterError(OutOfRangeError, LookupError):
    """A K number outside K20..K89: the motor answers error00 (Out Of Range)."""


@dataclass(frozen=True, slots=True)
class ParamSpec:
    """One K parameter as a manual table row gives it.

    ``digit_ranges`` (kind ``digits``) lists the allowed range of each decimal
    digit, ones digit first: for the per-input parameters the ones digit is
    input 1 (ch. 3 K25: "in order of Input 6,5,4,3,2,1").
    """

    k: int
    name: str
    min: int
    max: int
    default: int
    unit: str = "-"
    description: str = ""
    kind: ParamKind = "range"
    digit_ranges: tuple[tuple[int, int], ...] = ()
    choices: frozenset[int] = frozenset()

    def __post_init__(self) -> None:
        if not self.accepts(self.default):
            raise ValueError(f"K{self.k}: default {self.default} is not a valid value")

    def accepts(self, value: int) -> bool:
        """Whether ``value`` is a value this parameter can take."""
        if isinstance(value, bool) or not isinstance(value, int):
            return False
        if self.kind == "digits":
            return _digits_ok(value, self.digit_ranges)
        if self.kind == "choice":
            return value in self.choices
        return self.min <= value <= self.max

    def check(self, value: int) -> None:
        """Raise :class:`OutOfRangeError` unless ``value`` is accepted."""
        if not self.accepts(value):
            raise OutOfRangeError(f"K{self.k}={value!r} is out of range")

    @property
    def reserved(self) -> bool:
        """A number table 6.1 (or the profile's manual) does not define."""
        return self.kind == "reserved"


def _digits_ok(value: int, ranges: tuple[tuple[int, int], ...]) -> bool:
    if value < 0 or value >= 10 ** len(ranges):
        return False
    for lo, hi in ranges:
        digit = value % 10
        if not lo <= digit <= hi:
            return False
        value //= 10
    return True


# -- builders used by the firmware tables ----------------------------------------

def ranged(k: int, name: str, lo: int, hi: int, default: int, unit: str = "-",
           description: str = "") -> ParamSpec:
    """A plain min..max parameter."""
    return ParamSpec(k, name, lo, hi, default, unit, description)


def digitwise(k: int, name: str, ranges: tuple[tuple[int, int], ...], default: int,
              unit: str = "-", description: str = "") -> ParamSpec:
    """A parameter validated digit by digit; ``ranges`` is ones digit first."""
    lo = int("".join(str(r[0]) for r in reversed(ranges)))
    hi = int("".join(str(r[1]) for r in reversed(ranges)))
    return ParamSpec(k, name, lo, hi, default, unit, description, "digits", ranges)


def per_channel(k: int, name: str, channels: int, lo: int, hi: int, default_digit: int,
                unit: str = "-", description: str = "") -> ParamSpec:
    """One digit per input or output, every digit in ``lo..hi`` (K25-K34)."""
    default = int(str(default_digit) * channels)
    return digitwise(k, name, ((lo, hi),) * channels, default, unit, description)


def chosen(k: int, name: str, choices: frozenset[int], default: int, unit: str = "-",
           description: str = "") -> ParamSpec:
    """A parameter that takes one of a listed set of values."""
    return ParamSpec(k, name, min(choices), max(choices), default, unit, description,
                     "choice", (), choices)


def reserved(k: int, value: int = 0) -> ParamSpec:
    """A number the manual does not define: reads ``value``, accepts only it."""
    return ParamSpec(k, "(reserved)", value, value, value, "-",
                     "not defined by the manual; fixed value", "reserved")


# -- the per-motor table ---------------------------------------------------------

class ParamTable:
    """The K20..K89 values of one motor, validated against its firmware's specs.

    Listeners registered with :meth:`on_change` are called as
    ``callback(k, old, new)`` after every accepted write, also when the value is
    unchanged (a rewrite of K20 still prints the baud-rate prompt, a rewrite of
    K65 on ID1 still propagates).  :meth:`restore` and :meth:`reset` (power-up
    load) do not call listeners.
    """

    def __init__(self, firmware: Firmware | None = None) -> None:
        if firmware is None:
            from .firmware import CM2  # noqa: PLC0415  (firmware imports this module)
            firmware = CM2
        self._firmware = firmware
        self._specs: dict[int, ParamSpec] = {s.k: s for s in firmware.params}
        missing = [k for k in range(FIRST_K, LAST_K + 1) if k not in self._specs]
        if missing:
            raise ValueError(f"firmware {firmware.name!r} lacks specs for K{missing}")
        self._values: dict[int, int] = self.defaults()
        self._listeners: list[ChangeListener] = []

    @property
    def firmware(self) -> Firmware:
        """The profile whose specs this table enforces."""
        return self._firmware

    def spec(self, k: int) -> ParamSpec:
        """The spec of K``k``; :class:`NoSuchParameterError` outside K20..K89."""
        try:
            return self._specs[k]
        except (KeyError, TypeError):
            raise NoSuchParameterError(f"K{k} does not exist") from None

    def get(self, k: int) -> int:
        """The current value of K``k``."""
        try:
            return self._values[k]          # holds exactly the K numbers of the specs
        except (KeyError, TypeError):
            raise NoSuchParameterError(f"K{k} does not exist") from None

    def __getitem__(self, k: int) -> int:
        return self.get(k)

    def check(self, k: int, value: int) -> None:
        """Validate without applying (raises :class:`OutOfRangeError`)."""
        self.spec(k).check(value)

    def set(self, k: int, value: int) -> int:
        """Apply ``value`` to K``k`` and return the old value.

        An out-of-range value raises :class:`OutOfRangeError` and is not
        reflected (ch. 3).  Listeners run after the value is applied.
        """
        self.check(k, value)
        old = self._values[k]
        self._values[k] = value
        for listener in tuple(self._listeners):
            listener(k, old, value)
        return old

    def items(self) -> Iterator[tuple[int, int]]:
        """``(k, value)`` pairs in K order."""
        return iter(sorted(self._values.items()))

    def values(self) -> dict[int, int]:
        """A copy of all current values."""
        return dict(self._values)

    def defaults(self) -> dict[int, int]:
        """The factory values of this firmware (table 6.1 "Default")."""
        return {k: s.default for k, s in sorted(self._specs.items())}

    def on_change(self, callback: ChangeListener) -> Callable[[], None]:
        """Call ``callback(k, old, new)`` after each accepted write.

        Returns a function that removes the listener again.
        """
        self._listeners.append(callback)

        def remove() -> None:
            if callback in self._listeners:
                self._listeners.remove(callback)

        return remove

    def restore(self, values: Mapping[int, int]) -> list[int]:
        """Load saved values (power-up); no listeners run.

        Values that this firmware does not accept are skipped and keep their
        current value; their K numbers are returned.
        """
        rejected: list[int] = []
        for k, value in values.items():
            spec = self._specs.get(k)
            if spec is None or not spec.accepts(value):
                rejected.append(k)
                continue
            self._values[k] = value
        return sorted(rejected)

    def reset(self) -> None:
        """Back to the factory values; no listeners run."""
        self._values = self.defaults()

    def format_param(self, k: int, motor_id: int) -> str:
        """One parameter as the motor prints it: ``K20.1=0``."""
        return f"K{k}.{motor_id}={self.get(k)}"

    def format_param_listing(self, motor_id: int) -> list[str]:
        """The ``?90`` reply lines: K20..K89, four a line, ", " between (6.6)."""
        ks = list(range(FIRST_K, LAST_K + 1))
        return [", ".join(self.format_param(k, motor_id) for k in ks[i:i + PER_LINE])
                for i in range(0, len(ks), PER_LINE)]
