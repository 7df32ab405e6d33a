"""The motion solver's piece count on a command faster than top speed.

With K56 raised (ch. 3 K56) and S beyond the top speed, a move reversed while the
shaft runs at full speed was braked through zero speed onto the command's speed
with no top-speed exit: the shaft passed v_max and the modes after it chattered
(sat -> track -> vmax, 1 ns each) until the 2000-piece safety net held the motor
still.  The braking mode now ends at the top speed like the others.
"""

from __future__ import annotations

import logging

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.sim.kernel import ms

LINES = ["K56.1=32767", "S.1=7027", "A.1=7698", "P.1=1", "^.1", "P.1+=-500000", "^.1",
         "P.1+=-1", "^.1"]


@pytest.mark.parametrize("gap_ms", [50, 200, 1000])
def test_the_fuzzed_sequence_stays_far_below_the_piece_limit(
        gap_ms: int, caplog: pytest.LogCaptureFixture) -> None:
    counts: list[int] = []
    chain = Chain(motors=2)
    for motor in chain.motors.values():          # every motion each axis solves
        axis = motor.axis
        axis.trajectory_listeners.append(
            lambda axis=axis: counts.append(len(axis.motion.pieces)))
    with caplog.at_level(logging.WARNING):
        for line in LINES:
            chain.host_line.feed((line + "\r").encode())
            chain.kernel.run(until=chain.kernel.now + ms(gap_ms))
        chain.kernel.run(until=chain.kernel.now + ms(120_000))
    assert "piece limit" not in caplog.text
    assert counts and max(counts) < 100, max(counts)
    axis_speed = max(abs(chain.motors[1].axis.motion.velocity_at(chain.kernel.now - ms(t)))
                     for t in range(0, 100, 10))
    assert axis_speed == 0.0                           # standing (the K56 alarm or arrived)
