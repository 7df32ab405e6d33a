"""``Device.cyclic_state``: the values a fieldbus cycle reads (docs/device-api.md) are
those of the full ``snapshot`` at the same instant, through moves, I/O, servo off and an
origin search (cml-users-guide.txt 5.3; ethercat-bridge-users-guide.txt 6.3, 6.4)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coolmuscle.chain.daisy import Chain
from coolmuscle.device import CyclicState, Device
from coolmuscle.errors import NoSuchMotorError
from coolmuscle.sim.kernel import NS_PER_MS
from fixtures import ChainFactory


def same(chain: Chain, motor: int) -> None:
    snap, cyc = chain.snapshot(motor), chain.cyclic_state(motor)
    assert isinstance(cyc, CyclicState)
    assert (cyc.motor, cyc.time, cyc.position, cyc.speed_pps, cyc.status, cyc.inputs,
            cyc.outputs, cyc.enabled) == (snap.motor, snap.time, snap.position,
                                          snap.speed_pps, snap.status, snap.inputs,
                                          snap.outputs, snap.enabled)
    assert (int(cyc.origin_search), int(cyc.origin_done)) == (
        snap.extra["origin_search"], snap.extra["origin_done"])


@settings(max_examples=25, deadline=None)
@given(steps=st.lists(st.tuples(st.sampled_from(["move", "in", "out", "free", "enable",
                                                 "origin"]),
                                st.integers(-20_000, 20_000), st.integers(0, 300)),
                      min_size=1, max_size=12))
def test_the_cyclic_state_is_the_snapshot_of_the_same_instant(
        steps: list[tuple[str, int, int]]) -> None:
    chain = Chain(motors=2)
    assert isinstance(chain, Device)
    for action, value, gap_ms in steps:
        if action == "move":
            chain.execute(f"S.2=50, A.2=100, P.2={value}")
            chain.execute("^.2")
        elif action == "in":
            chain.set_input(2, 1 + abs(value) % 4, value > 0)
        elif action == "out":
            chain.execute(f"O.2={abs(value) % 16}")
        elif action == "free":
            chain.execute(").2")
        elif action == "enable":
            chain.execute("(.2")
        else:
            chain.execute("|.2")
        for _ in range(3):
            chain.kernel.advance(gap_ms * NS_PER_MS // 3 + 1)
            same(chain, 2)
            same(chain, 1)


def test_no_such_motor(make_chain: ChainFactory) -> None:
    with pytest.raises(NoSuchMotorError):
        make_chain(motors=1).cyclic_state(2)
