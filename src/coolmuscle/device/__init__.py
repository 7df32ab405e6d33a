"""The device API (:mod:`.api`), the host line every text front end feeds (:mod:`.hostline`),
the trace feed traces and plots read (:mod:`.trace`, imported when used: it needs the
motor model) and the wire faults every door asks (:mod:`.wire`, docs/wire-faults.md).

``from coolmuscle.device import Device, Event, MotorSnapshot`` is the stable import.
"""

from .api import (
                  ChainFactory,
                  Com1Line,
                  CyclicState,
                  Device,
                  Event,
                  EventKind,
                  EventListener,
                  MotorSnapshot,
                  Origin,
                  TargetStream,
)

__all__ = ["ChainFactory", "Com1Line", "CyclicState", "Device", "Event", "EventKind",
           "EventListener", "MotorSnapshot", "Origin", "TargetStream"]
