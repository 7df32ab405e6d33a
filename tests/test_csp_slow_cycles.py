"""No slow csp cycle of the model's making (ethercat-bridge-users-guide.txt 6.3: a new
target every 1 ms cycle): the motion command cache (``dynamics.command_pieces``) keeps a
command only once it has been seen again, and makes room one entry at a time, so csp,
whose commands never repeat, neither fills it nor has it emptied all at once (a cycle of
0.5-0.9 ms instead of 0.1 every 1,000-2,000 cycles); a repeated move still finds its
command.  Counted, not timed (the timing is bench/bench_ethercat_csp.py's).
"""

from __future__ import annotations

import struct
from typing import Any

import pytest

from coolmuscle.chain import Chain
from coolmuscle.motor.motion import dynamics


class _Counted(dict[Any, Any]):
    """The cache, counting what is found and what is dropped at once."""

    def __init__(self) -> None:
        super().__init__()
        self.hits = self.clears = self.most = 0

    def get(self, key: Any, default: Any = None) -> Any:
        found = super().get(key, default)
        self.hits += found is not None
        return found

    def __setitem__(self, key: Any, value: Any) -> None:
        super().__setitem__(key, value)
        self.most = max(self.most, len(self))

    def clear(self) -> None:
        self.clears += 1
        super().clear()


@pytest.fixture
def commands(monkeypatch: pytest.MonkeyPatch) -> _Counted:
    counted = _Counted()
    monkeypatch.setattr(dynamics, "_COMMANDS", counted)
    return counted


def test_csp_cycles_leave_the_command_cache_alone(commands: _Counted) -> None:
    """One axis following a triangle in csp for 5,000 cycles: every command is new; none
    is kept, the cache is never emptied."""
    from coolmuscle.frontends.ethercat.bridge.app import BridgeApp

    chain = Chain(None, 1, firmware="cm2")
    kernel = chain.kernel
    app = BridgeApp(chain, "EB02")
    od = app.dictionary

    def frame(controlword: int, target: int) -> None:
        data = struct.pack("<" + "Hi" * 4, *([controlword, target] * 4))
        od.unpack_outputs(data)
        app.outputs(data)

    app.start_cycles(1_000_000)
    for controlword in (0x06, 0x07, 0x0F):                 # to Operation enabled (6.1.2)
        frame(controlword, 0)
        kernel.run(until=kernel.now + 5_000_000)
    for cycle in range(5000):
        phase = cycle % 4000                               # +/-2,000 pulses, 2 a cycle
        frame(0x0F, 2 * phase if phase < 1000 else 4000 - 2 * phase if phase < 3000
              else 2 * phase - 8000)
        kernel.run(until=kernel.now + 1_000_000)
    position = chain.snapshot(1).position
    app.stop_cycles()
    chain.close()
    assert 1500 < position < 2100                         # following: near +2,000
    assert commands.clears == 0
    assert commands.most < 64, commands.most


def test_a_repeated_move_finds_its_command(commands: _Counted) -> None:
    """A bank looping two PTP moves: from the third cycle on each move's command is found."""
    chain = Chain(None, 1)
    for line in ("S1.1=100", "A1.1=100", "P1.1=3000", "P2.1=0", "B1.1", "X0",
                 "S1.1, A1.1, P1.1", "P2.1", "X-", "END", "[1.1"):
        chain.execute(line)
    chain.kernel.run(until=chain.kernel.now + 40 * 10**9)
    chain.close()
    assert commands.hits > 20, commands.hits
    assert commands.clears == 0
