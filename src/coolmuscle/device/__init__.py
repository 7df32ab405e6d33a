"""The device API (:mod:`.api`) and the host line every text front end feeds (:mod:`.hostline`).

``from coolmuscle.device import Device, Event, MotorSnapshot`` is the stable import.
"""

from .api import (CyclicState, Device, Event, EventKind, EventListener, MotorSnapshot,
                  Origin, TargetStream)

__all__ = ["CyclicState", "Device", "Event", "EventKind", "EventListener", "MotorSnapshot",
           "Origin", "TargetStream"]
