"""K parameters: the spec of one parameter (cml-users-guide.txt ch. 3, table 6.1).

This module owns how a K value is validated.  The spec tables themselves differ per
firmware and live in :mod:`.firmware`; the per-motor table (writes, listeners, the
``?90`` listing) is :mod:`.param_table`.

Ch. 3: "Each parameter has individual setting range.  The value out of the range
will not be reflected.  The changed value is saved automatically."  So
:meth:`ParamTable.set` either applies a value completely or raises
:class:`~coolmuscle.errors.OutOfRangeError` and changes nothing; persistence is
the motor's job, through :meth:`ParamTable.on_change`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from ...errors import OutOfRangeError

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

    def accepts(self, value: object) -> bool:
        """Whether ``value`` is a value this parameter can take."""
        if isinstance(value, bool) or not isinstance(value, int):
            return False
        if self.kind == "digits":
            return _digits_ok(value, self.digit_ranges)
        if self.kind == "choice":
            return value in self.choices
        return self.min <= value <= self.max

    def check(self, value: object) -> None:
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
