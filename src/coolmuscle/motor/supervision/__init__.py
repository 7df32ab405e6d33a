"""Supervision: alarms, driver temperature, travel limits, injected faults, origin search (5.3)
and push motion (4.1.4); :mod:`.mixin` is the part of the motor that runs them."""
