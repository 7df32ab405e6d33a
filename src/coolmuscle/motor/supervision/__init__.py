"""Supervision: alarms, driver temperature, travel limits, injected faults, origin search (5.3)
and push motion (4.1.4); :mod:`.supervisor` runs them for the motor."""
