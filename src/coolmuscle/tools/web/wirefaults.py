"""The dashboard's wire-fault panel: the vocabulary for the page, its requests to the device.

The page builds its controls from :func:`vocabulary` (every door, its fault kinds and
their parameters: :mod:`coolmuscle.device.wire.vocabulary`, the registry the machine file
checks against too) and sends three requests, each answered with the faults installed
now:

* ``{"t": "wire_fault", "door": ..., "kind": ..., "schedule": {...}, "params": {...}}``
  installs one through ``Device.inject_wire_fault`` (``schedule``: ``at``, ``until``,
  ``every``, ``probability``, ``seed``, ``count``, ``motor``; seconds from now);
* ``{"t": "wire_clear", "fault": N}`` ends fault N, or every fault without ``fault``;
* ``{"t": "wire_faults"}`` lists them.

What a fault does is an event of kind ``wire`` (the page's log shows it as any event).
A bad request is a :class:`~.actions.RequestError` with the model's own message.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from ...device import Device
from ...device.wire import SCHEDULE_KEYS, describe
from .actions import RequestError

__all__ = ["WirePanel", "vocabulary"]

Handler = Callable[[dict[str, Any]], dict[str, Any]]
#: The schedule keys a request may give (door and kind are its own fields).
_SCHEDULE = frozenset(SCHEDULE_KEYS[2:])


def vocabulary() -> dict[str, Any]:
    """Every door and kind with its parameters, for the page's ``hello``."""
    return {"doors": describe(), "schedule": list(SCHEDULE_KEYS[2:])}


def _value_ok(value: Any) -> bool:
    if isinstance(value, float):
        return math.isfinite(value)
    return isinstance(value, (bool, int)) or (isinstance(value, str) and len(value) <= 16)


class WirePanel:
    """The panel's request handlers; ``call`` runs a model call at the current instant."""

    def __init__(self, device: Device, call: Callable[..., Any]) -> None:
        self.device = device
        self._call = call

    def handlers(self) -> dict[str, Handler]:
        return {"wire_fault": self.inject, "wire_clear": self.clear,
                "wire_faults": self.faults}

    def _table(self, request: dict[str, Any], key: str, keys: frozenset[str] | None
               ) -> dict[str, Any]:
        table = request.get(key, {})
        if not isinstance(table, dict) or len(table) > 16:
            raise RequestError(f"wire_fault: {key!r} must be an object")
        if keys is not None:
            unknown = sorted(set(table) - keys)
            if unknown:
                raise RequestError(f"wire_fault: {unknown[0][:20]!r} is no schedule key "
                                   f"({', '.join(sorted(keys))})")
        if not all(isinstance(k, str) and (v is None or _value_ok(v))
                   for k, v in table.items()):
            raise RequestError("wire_fault: values are numbers, true/false or short text")
        return {k: v for k, v in table.items() if v is not None}

    def inject(self, request: dict[str, Any]) -> dict[str, Any]:
        door, kind = request.get("door"), request.get("kind")
        if not isinstance(door, str) or not isinstance(kind, str):
            raise RequestError("wire_fault: 'door' and 'kind' are names (docs/wire-faults.md)")
        schedule = self._table(request, "schedule", _SCHEDULE)
        params = self._table(request, "params", None)
        taken = sorted(set(params) & (_SCHEDULE | {"door", "kind"}))
        if taken:                        # a schedule key or a name is no fault parameter
            raise RequestError(f"wire_fault: {taken[0]!r} is no parameter of a fault "
                               "(the schedule's keys go in 'schedule')")
        number = self._call(lambda: self.device.inject_wire_fault(
            door, kind, **schedule, **params))
        return {"fault": number, **self.faults(request)}

    def clear(self, request: dict[str, Any]) -> dict[str, Any]:
        number = request.get("fault")
        if number is not None and (not isinstance(number, int) or isinstance(number, bool)):
            raise RequestError("wire_clear: 'fault' is a fault's number")
        cleared = self._call(lambda: self.device.clear_wire_faults(number))
        return {"cleared": cleared, **self.faults(request)}

    def faults(self, _request: dict[str, Any]) -> dict[str, Any]:
        return {"faults": self._call(self.device.wire_faults.describe)}
