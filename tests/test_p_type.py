"""P type operation on a C/R type motor (cml-users-guide.txt ch. 3 K26 ②, K36): the
command pulse train on inputs 1 and 2 moves the motor one pulse per effective edge."""

from __future__ import annotations

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.sim.kernel import NS_PER_S
from fixtures import ChainFactory


def pulses(chain: Chain, count: int, number: int = 1) -> int:
    """``count`` pulses (0.5 ms high, 0.5 ms low) on input ``number``; Px after 0.5 s."""
    kernel = chain.kernel
    for _ in range(count):
        chain.set_input(1, number, True)
        kernel.run(until=kernel.now + 500_000)
        chain.set_input(1, number, False)
        kernel.run(until=kernel.now + 500_000)
    kernel.run(until=kernel.now + NS_PER_S // 2)
    return chain.snapshot(1).position


def test_k26_xxxx22_p_type_at_all_times_cw_ccw_pulses(make_chain: ChainFactory) -> None:
    """K26 "XXXX22: P type Operation Only"; K36=0 "rising edge of Input Signal 1, count
    up in CW direction ... Input Signal 2, count up in CCW direction"."""
    chain = make_chain()
    chain.execute("K26.1=000022")
    assert pulses(chain, 5) == 5
    assert pulses(chain, 2, number=2) == 3


def test_k26_3_counts_the_falling_edge_of_the_port(make_chain: ChainFactory) -> None:
    """K26 1/3: "Effective edge: Falling edge of input port" (the signal's rising edge)."""
    chain = make_chain()
    chain.execute("K26.1=000033")
    kernel = chain.kernel
    chain.set_input(1, 1, True)                 # port on: signal off (inverted logic)
    kernel.run(until=kernel.now + NS_PER_S // 10)
    assert chain.snapshot(1).position == 0
    chain.set_input(1, 1, False)                # falling edge of the port: one pulse
    kernel.run(until=kernel.now + NS_PER_S // 2)
    assert chain.snapshot(1).position == 1


def test_k26_2xxx00_p_type_only_while_input_6_is_on(make_chain: ChainFactory) -> None:
    """K26 "2XXX00": "P type Operation is executed as long as the input signal is ON"."""
    chain = make_chain()
    chain.execute("K26.1=200000")
    assert pulses(chain, 5) == 0                # input 6 off: pulses refused
    chain.set_input(1, 6, True)
    assert pulses(chain, 5) == 5


def test_k36_1_pulse_and_direction(make_chain: ChainFactory) -> None:
    """K36 1: "Input Signal 1 to command pulse, Input Signal 2 to direction"."""
    chain = make_chain()
    chain.execute("K26.1=000022")
    chain.execute("K36.1=1")
    assert pulses(chain, 3) == -3               # input 2 off: CCW
    chain.set_input(1, 2, True)
    assert pulses(chain, 5) == 2                # input 2 on: CW


def test_no_p_type_while_a_program_bank_runs(make_chain: ChainFactory) -> None:
    """"During the execution of Bank Program, it can not be switched to P type"."""
    chain = make_chain()
    chain.execute("K26.1=200000")
    for line in ("B1.1", "T1.1=5000", "T1.1", "END"):
        chain.execute(line)
    chain.execute("[1.1")
    chain.set_input(1, 6, True)
    assert pulses(chain, 4) == 0


def test_a_host_motion_has_priority_over_the_pulses(make_chain: ChainFactory) -> None:
    """"When COOL MUSCLE receives commands from the host during P type Operation, the
    processing of the command is given priority and executed"."""
    chain = make_chain()
    chain.execute("K26.1=000022")
    for line in ("S.1=10", "A.1=100", "P.1=3000", "^.1"):
        chain.execute(line)
    chain.kernel.run(until=chain.kernel.now + NS_PER_S // 10)
    assert pulses(chain, 3) > 3                 # the move goes on, not a 3-pulse step
    chain.kernel.run(until=chain.kernel.now + 10 * NS_PER_S)
    assert chain.snapshot(1).position == 3000
    assert pulses(chain, 2) == 3002             # then the pulses count again


@pytest.mark.parametrize("k26", ["000000", "000011"])
def test_without_digit_2_or_3_inputs_1_and_2_are_ordinary_inputs(
        k26: str, make_chain: ChainFactory) -> None:
    chain = make_chain()
    chain.execute(f"K26.1={k26}")
    assert pulses(chain, 5) == 0
