"""The per-motor K parameter table (cml-users-guide.txt ch. 3, table 6.1, ?90 of 6.6).

Ch. 3: "Each parameter has individual setting range.  The value out of the range
will not be reflected.  The changed value is saved automatically."  So
:meth:`ParamTable.set` either applies a value completely or raises
:class:`~coolmuscle.errors.OutOfRangeError` and changes nothing; persistence is
the motor's job, through :meth:`ParamTable.on_change`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Any

from .firmware import CM2, Firmware
from .params import FIRST_K, LAST_K, PER_LINE, ChangeListener, NoSuchParameterError, ParamSpec

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
            firmware = CM2
        self._firmware = firmware
        self._specs: dict[int, ParamSpec] = {s.k: s for s in firmware.params}
        missing = [k for k in range(FIRST_K, LAST_K + 1) if k not in self._specs]
        if missing:
            raise ValueError(f"firmware {firmware.name!r} lacks specs for K{missing}")
        self._values: dict[int, int] = self.defaults()
        self._listeners: list[ChangeListener] = []
        #: Counts the writes (set, restore, reset): what is derived from the values can
        #: be kept while it is unchanged (``Motor.limits``, ``TravelLimits``).
        self.version = 0

    @property
    def firmware(self) -> Firmware:
        """The profile whose specs this table enforces."""
        return self._firmware

    # ``k`` is any object, looked up as a dict key (37.0 and numpy's 37 find K37, a
    # string or None finds nothing): compiled (coolmuscle/_accel.py), a typed ``int``
    # would turn those into a TypeError before the lookup could answer.
    def spec(self, k: object) -> ParamSpec:
        """The spec of K``k``; :class:`NoSuchParameterError` outside K20..K89."""
        specs: Any = self._specs
        try:
            found: ParamSpec = specs[k]
            return found
        except (KeyError, TypeError):
            raise NoSuchParameterError(f"K{k} does not exist") from None

    def get(self, k: object) -> int:
        """The current value of K``k``."""
        values: Any = self._values
        try:
            found: int = values[k]          # holds exactly the K numbers of the specs
            return found
        except (KeyError, TypeError):
            raise NoSuchParameterError(f"K{k} does not exist") from None

    def __getitem__(self, k: object) -> int:
        return self.get(k)

    def check(self, k: object, value: object) -> None:
        """Validate without applying (raises :class:`OutOfRangeError`)."""
        self.spec(k).check(value)

    def set(self, k: object, value: object) -> int:
        """Apply ``value`` to K``k`` and return the old value.

        An out-of-range value (or one that is not an integer) raises
        :class:`OutOfRangeError` and is not reflected (ch. 3).  Listeners run after
        the value is applied.
        """
        spec = self.spec(k)
        spec.check(value)
        assert isinstance(value, int)             # check() refuses anything else
        number = spec.k                           # listeners get the K number as an int
        old = self._values[number]
        self._values[number] = value
        self.version += 1
        for listener in tuple(self._listeners):
            listener(number, old, value)
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

    def restore(self, values: Mapping[Any, Any]) -> list[int]:
        """Load saved values (power-up); no listeners run.

        Values that this firmware does not accept are skipped and keep their
        current value; their K numbers are returned.
        """
        rejected: list[Any] = []
        table: Any = self._values
        for k, value in values.items():
            spec = self._specs.get(k)
            if spec is None or not spec.accepts(value):
                rejected.append(k)
                continue
            table[k] = value
        self.version += 1
        return sorted(rejected)

    def reset(self) -> None:
        """Back to the factory values; no listeners run."""
        self._values = self.defaults()
        self.version += 1

    def format_param(self, k: int, motor_id: int) -> str:
        """One parameter as the motor prints it: ``K20.1=0``."""
        return f"K{k}.{motor_id}={self.get(k)}"

    def format_param_listing(self, motor_id: int) -> list[str]:
        """The ``?90`` reply lines: K20..K89, four a line, ", " between (6.6)."""
        ks = list(range(FIRST_K, LAST_K + 1))
        return [", ".join(self.format_param(k, motor_id) for k in ks[i:i + PER_LINE])
                for i in range(0, len(ks), PER_LINE)]
