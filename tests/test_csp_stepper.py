"""A stepper (CM1) in cyclic synchronous position mode: one target each cycle.

ethercat-bridge-users-guide.txt 6.3 (a target every 1 ms); docs/fidelity.md "csp on a
stepper" (the CM1 ramps to each target over the cycle; a step would lose its steps).
"""

from __future__ import annotations

from coolmuscle.chain import Chain

MS = 1_000_000


def _stream(period_ns: int, cycles: int = 500) -> tuple[Chain, list[float]]:
    chain = Chain(None, 1, firmware="cm1")
    chain.kernel.run(until=10 * MS)
    stream = chain.target_stream(1, period_ns)
    lag = []
    for i in range(1, cycles + 1):
        stream.push(2 * i)                              # 2,000 pps
        chain.kernel.advance(MS)
        lag.append(2 * i - chain.motors[1].axis.raw_actual())
    chain.kernel.advance(100 * MS)
    return chain, lag


def test_a_stepper_ramps_to_each_target_over_the_cycle_and_keeps_its_steps():
    chain, lag = _stream(MS)
    snap = chain.snapshot(1)
    assert snap.position == 1000 and snap.position_error == 0
    assert snap.status & 0x08 and not snap.status & 0x01           # in position, no alarm
    assert max(abs(e) for e in lag) < 1e-6                        # on the command each cycle


def test_a_stepper_given_steps_without_a_period_still_loses_them():
    """``Dx`` and a stream of unknown period step the command (unchanged)."""
    chain, lag = _stream(0, 50)
    assert chain.snapshot(1).position == 0 and lag[-1] == 100
