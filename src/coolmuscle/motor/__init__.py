"""One COOL MUSCLE: the only place motor behaviour lives (docs/architecture.md).

- :mod:`.motor`: the façade, :class:`~.motor.Motor`; :mod:`.status`: Ux bits (6.6 ?99);
  :mod:`.context`: who executes a line, and what a motor needs of its chain.
- :mod:`.state`: K parameters, firmware profiles, data memory, units, the store (ch. 3, 6.1, 6.2).
- :mod:`.motion`: command profiles, planner, servo and load model, the axis, interpolation geometry.
- :mod:`.programs`: CML execution: direct mode, queries, program and ladder banks (ch. 2, 4, 6).
- :mod:`.signals`: inputs, outputs, analog, encoder, rotation pulses, jog (ch. 5).
- :mod:`.supervision`: alarms, temperature, travel limits, faults, origin search, push (ch. 4, 5).
"""
