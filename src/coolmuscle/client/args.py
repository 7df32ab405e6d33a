"""Arguments of the host library, checked before anything is sent (sans-IO).

A wrong type or a missing value is the caller's mistake, not the motor's: it raises
:class:`~coolmuscle.errors.InvalidArgumentError` (a ``ValueError``) naming the
argument, instead of a ``TypeError`` from deep inside the library, or worse, a line the
motor takes for something else (``move_to(None)`` would send a bare ``^.1`` and repeat
the last target).  Ranges stay with the firmware tables (:mod:`.commands`).
"""

from __future__ import annotations

import math
import numbers
import operator

from ..device.hostline import MAX_LINE
from ..errors import InvalidArgumentError

__all__ = ["integer", "optional_integer", "seconds", "motor_id", "line", "flag"]


def integer(name: str, value: object) -> int:
    """An integer (``int`` or one that says it is, as numpy's do: ``__index__``); not
    a bool, a float or a numeric string."""
    if isinstance(value, bool):
        raise InvalidArgumentError(f"{name} must be an integer, not {value!r}")
    try:
        return operator.index(value)    # type: ignore[arg-type]
    except TypeError:
        raise InvalidArgumentError(f"{name} must be an integer, not {value!r}") from None


def optional_integer(name: str, value: object) -> int | None:
    """An ``int`` or ``None`` (the motor's current value is kept)."""
    return None if value is None else integer(name, value)


def seconds(name: str, value: object, *, allow_none: bool = False) -> float | None:
    """A finite, non-negative number of seconds."""
    if value is None and allow_none:
        return None
    if isinstance(value, (bool, str, bytes)) or not isinstance(value, numbers.Real) \
            or math.isnan(value) or value < 0:
        raise InvalidArgumentError(f"{name} must be a number of seconds >= 0, not {value!r}")
    return float(value)         # inf: wait for as long as it takes


def motor_id(value: object) -> int:
    """A motor ID of the chain, 1..15 (cml-users-guide.txt 1.1)."""
    try:
        number = integer("a motor ID", value)
    except InvalidArgumentError:
        number = 0
    if not 1 <= number <= 15:
        raise InvalidArgumentError(f"a motor ID is 1..15 (cml-users-guide.txt 1.1), "
                                   f"not {value!r}")
    return number


def line(value: object) -> str:
    """One CML line: text without a line end, of single bytes (the line is 8-bit)."""
    if not isinstance(value, str):
        raise InvalidArgumentError(f"a CML line is a str, not {value!r}")
    if "\r" in value or "\n" in value:
        raise InvalidArgumentError(f"one CML line at a time (no CR or LF): {value!r}")
    try:
        value.encode("latin-1")
    except UnicodeEncodeError:
        raise InvalidArgumentError(f"a CML line holds single-byte characters only: "
                                   f"{value!r}") from None
    if len(value) > MAX_LINE:
        raise InvalidArgumentError(f"a CML line of {len(value)} characters: the motor "
                                   f"discards lines over {MAX_LINE} (docs/fidelity.md "
                                   "\"Over-long lines\")")
    return value


def flag(name: str, value: object) -> bool:
    """A ``bool`` (0 and 1 accepted as such)."""
    if isinstance(value, bool):
        return value
    if type(value).__module__ == "numpy" and type(value).__name__ in ("bool", "bool_"):
        return bool(value)
    try:
        number = integer(name, value)
    except InvalidArgumentError:
        number = -1
    if number in (0, 1):
        return bool(number)
    raise InvalidArgumentError(f"{name} must be True or False, not {value!r}")
