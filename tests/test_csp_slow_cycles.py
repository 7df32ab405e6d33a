"""No slow csp cycle of the model's making (ethercat-bridge-users-guide.txt 6.3: a new
target every 1 ms cycle): the chain's memo of motion commands
(``dynamics.command_pieces``, ``MotionMemos.commands``) does not keep a hold (csp's
command, at a new position every cycle, never found again) and makes room one answer at
a time, so no cycle pays for emptying it all (a cycle of 0.5-0.9 ms instead of 0.1
every 1,000-2,000 cycles); a repeated move still finds its command.  Counted, not timed
(the timing is bench/bench_ethercat_csp.py's); the memo is read, not hooked, so compiled
and source modules are checked alike.
"""

from __future__ import annotations

import struct

from coolmuscle.chain import Chain
from coolmuscle.motor.motion import dynamics
from coolmuscle.motor.motion.dynamics import MotionMemos
from coolmuscle.motor.motion.planner import Waypoint, limits_from_data, plan_moves
from coolmuscle.motor.motion.profile import hold

LIMITS = limits_from_data(100, 100, k37=3, k44=100, k51=0, k69=0)


def test_csp_cycles_leave_the_command_memo_alone() -> None:
    """One axis following a triangle in csp for 5,000 cycles: the chain's command memo
    never grows by a cycle's command and is never emptied at once."""
    from coolmuscle.frontends.ethercat.bridge.app import BridgeApp

    chain = Chain(None, 1, firmware="cm2")
    kernel = chain.kernel
    app = BridgeApp(chain, "EB02")
    od = app.dictionary
    commands = chain.motion_memos.commands

    def frame(controlword: int, target: int) -> None:
        data = struct.pack("<" + "Hi" * 4, *([controlword, target] * 4))
        od.unpack_outputs(data)
        app.outputs(data)

    app.start_cycles(1_000_000)
    for controlword in (0x06, 0x07, 0x0F):                 # to Operation enabled (6.1.2)
        frame(controlword, 0)
        kernel.run(until=kernel.now + 5_000_000)
    sizes = []
    for cycle in range(5000):
        phase = cycle % 4000                               # +/-2,000 pulses, 2 a cycle
        frame(0x0F, 2 * phase if phase < 1000 else 4000 - 2 * phase if phase < 3000
              else 2 * phase - 8000)
        kernel.run(until=kernel.now + 1_000_000)
        sizes.append(len(commands))
    position = chain.snapshot(1).position
    app.stop_cycles()
    chain.close()
    assert 1500 < position < 2100                         # following: near +2,000
    assert max(sizes) < 64, max(sizes)
    drops = [a - b for a, b in zip(sizes, sizes[1:], strict=False) if a > b]
    assert max(drops, default=0) <= 1, max(drops)


def test_a_hold_is_built_not_kept() -> None:
    memos = MotionMemos()
    profile = hold(1234.0, 0)
    first = dynamics.command_pieces(profile, 1_000_000, memos)
    assert dynamics.command_pieces(profile, 1_000_000, memos) == first
    assert (len(memos.commands), memos.commands.misses) == (0, 0)     # never looked up


def test_a_repeated_move_finds_its_command() -> None:
    """The same plan seen from the same offset: the second call gives the pieces kept by
    the first (the very objects; a new build makes new ones)."""
    memos = MotionMemos()
    profile = plan_moves((0.0, 0.0, 0.0), [Waypoint(3000.0, LIMITS)], 0)
    first = dynamics.command_pieces(profile, 0, memos)
    again = dynamics.command_pieces(profile, 0, memos)
    assert len(first) > 2 and again == first
    assert all(a is b for a, b in zip(first, again, strict=True))
    assert (len(memos.commands), memos.commands.hits) == (1, 1)


def test_a_full_memo_drops_its_oldest_command() -> None:
    """Past its size the memo drops one answer, the oldest, per new command; before, the
    table was emptied at once."""
    size = 16
    memos = MotionMemos(size)
    profiles = [plan_moves((0.0, 0.0, 0.0), [Waypoint(float(1000 + n), LIMITS)], 0)
                for n in range(size + 3)]
    kept = [dynamics.command_pieces(profile, 0, memos) for profile in profiles]
    assert len(memos.commands) == size
    for n in [*range(3, size + 3), *range(3)]:      # the three oldest last: built anew
        again = dynamics.command_pieces(profiles[n], 0, memos)
        assert again == kept[n]
        assert all(a is b for a, b in zip(kept[n], again, strict=True)) == (n >= 3), n
    assert (memos.commands.hits, memos.commands.misses) == (size, size + 3 + 3)
