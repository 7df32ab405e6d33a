"""Figures of one run for ``coolmuscle sweep`` / ``batch --results`` (docs/batch.md).

Per motor ``m<ID>.``: ``final_position`` (pulses), ``peak_speed`` (|pulses/s|),
``peak_torque`` (|% rated|), ``peak_temperature`` (°C, the ?71 reading, cml-users-guide
6.6), ``in_position`` (the virtual instants, seconds, at which Ux gained the
in-position bit 8, 6.6 ?99) and ``alarms`` (the Ux alarm bits seen, ch. 3 K56/K57).

Position, speed, torque and status come from the chain's trace recorder
(:class:`coolmuscle.tools.trace.recorder.TraceRecorder`) sampled exactly as ``coolmuscle run
--trace`` samples it (a 1 ms grid plus every change), so a figure equals what that
trace file shows; a run longer than 200 virtual seconds is sampled on a grid of
1/200,000 of its length (plus every change) instead, so its figures stay bounded in
time and memory.  The temperature is read through the device API
(``Device.snapshot``) after every kernel event.
"""

from __future__ import annotations

import logging

from ...device.api import Device
from ...motor.status import ALARM_BITS, Ux
from ...sim.kernel import NS_PER_S
from ..trace.recorder import FIELDS as TRACE_FIELDS
from ..trace.recorder import record

log = logging.getLogger(__name__)

#: Trace grid of the figures: the same step as ``coolmuscle run --trace``.
TRACE_STEP = 0.001

#: Most grid samples of one run's figures: a run longer than MAX_GRID ms of virtual
#: time is sampled on a coarser grid (every change is still a sample).
MAX_GRID = 200_000

#: Figure names per motor, in column order.
FIGURES = ("final_position", "peak_speed", "peak_torque", "peak_temperature",
           "in_position", "alarms")

_ALARM_NAMES = tuple((int(flag), flag.name.lower()) for flag in Ux
                     if flag.value and flag.value & int(ALARM_BITS) and flag.name)


def grid_step(duration_ns: int) -> float:
    """``TRACE_STEP`` (1 ms), or ``duration / MAX_GRID`` for a run over 200 s."""
    return max(TRACE_STEP, duration_ns / NS_PER_S / MAX_GRID)


def alarm_names(bits: int) -> str:
    """``4 | 128`` -> ``"overload;temperature"`` (Ux alarm bits, 6.6 ?99)."""
    return ";".join(name for bit, name in _ALARM_NAMES if bits & bit)


class FigureProbe:
    """Attached to a chain before a run; :meth:`figures` after it."""

    def __init__(self, chain: Device) -> None:
        self.chain = chain
        self.recorder = record(chain)
        self.ids: tuple[int, ...] = tuple(chain.motor_ids)
        self.peak_temperature = {m: chain.snapshot(m).temperature for m in self.ids}
        self._remove = chain.kernel.add_observer(self._observe)

    def _observe(self) -> None:
        for motor in self.ids:
            temperature = self.chain.snapshot(motor).temperature
            if temperature > self.peak_temperature[motor]:
                self.peak_temperature[motor] = temperature

    def figures(self) -> dict[str, object]:
        """Stop observing and return ``{"m1.final_position": ..., ...}`` (one pass over
        the trace rows, never held in memory)."""
        self._remove()
        self._observe()
        width = len(TRACE_FIELDS)
        columns = [tuple(1 + i * width + TRACE_FIELDS.index(name)
                         for name in ("position", "speed", "torque", "status"))
                   for i in range(len(self.ids))]
        final = [0.0] * len(self.ids)
        speed = [0.0] * len(self.ids)
        torque = [0.0] * len(self.ids)
        alarms = [0] * len(self.ids)
        arrivals: list[list[str]] = [[] for _ in self.ids]
        before = [True] * len(self.ids)  # in position at the start is no arrival
        alarm_bits, in_position = int(ALARM_BITS), int(Ux.IN_POSITION)
        for row in self.recorder.rows(grid_step(self.chain.kernel.now - self.recorder.start)):
            for i, (p, v, t, st) in enumerate(columns):
                final[i] = row[p]
                speed[i] = max(speed[i], abs(row[v]))
                torque[i] = max(torque[i], abs(row[t]))
                status = int(row[st])
                alarms[i] |= status & alarm_bits
                now = bool(status & in_position)
                if now and not before[i]:
                    arrivals[i].append(f"{row[0]:.6f}")
                before[i] = now
        out: dict[str, object] = {}
        for i, motor in enumerate(self.ids):
            prefix = f"m{motor}."
            out[prefix + "final_position"] = final[i]
            out[prefix + "peak_speed"] = speed[i]
            out[prefix + "peak_torque"] = torque[i]
            out[prefix + "peak_temperature"] = self.peak_temperature[motor]
            out[prefix + "in_position"] = ";".join(arrivals[i])
            out[prefix + "alarms"] = alarm_names(alarms[i])
        return out


def ns_to_seconds(ns: int) -> str:
    """Virtual time as text, to the nanosecond (``"1.100000000"``)."""
    whole, frac = divmod(int(ns), NS_PER_S)
    return f"{whole}.{frac:09d}"
