"""The bounded memo (coolmuscle/sim/memo.py, docs/architecture.md "Fast code"): first in,
first out, counted, forgotten by ``clear_caches()``; a chain's memos are its own."""

from __future__ import annotations

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.sim.kernel import seconds
from coolmuscle.sim.memo import Memo, clear_caches


def test_a_full_memo_drops_its_oldest_answer_only() -> None:
    memo: Memo[str, int] = Memo(3)
    for i, key in enumerate("abc"):
        assert memo.put(key, i) == i
    memo.put("d", 3)
    assert len(memo) == 3
    assert memo.get("a") is None
    assert [memo.get(k) for k in "bcd"] == [1, 2, 3]


def test_a_hit_moves_nothing_and_a_known_key_takes_no_room() -> None:
    memo: Memo[str, int] = Memo(2)
    memo.put("a", 1)
    memo.put("b", 2)
    assert memo.get("a") == 1              # first in stays first out
    memo.put("b", 20)                      # replaced in place: nothing dropped
    assert (memo.get("a"), memo.get("b")) == (1, 20)
    memo.put("c", 3)
    assert (memo.get("a"), memo.get("b"), memo.get("c")) == (None, 20, 3)


def test_two_keys_of_one_hash_never_answer_for_each_other() -> None:
    assert hash(-1) == hash(-2)            # CPython: -1 is the error value of a hash
    memo: Memo[int, str] = Memo(4)
    memo.put(-1, "minus one")
    assert memo.get(-2) is None
    memo.put(-2, "minus two")              # takes the place of -1
    assert (memo.get(-1), memo.get(-2), len(memo)) == (None, "minus two", 1)


def test_hits_and_misses_are_counted_until_cleared() -> None:
    memo: Memo[int, str] = Memo(4)
    assert memo.get(1) is None
    memo.put(1, "one")
    assert memo.get(1) == "one"
    assert (memo.hits, memo.misses) == (1, 1)
    memo.clear()
    assert (len(memo), memo.hits, memo.misses) == (0, 0, 0)
    assert memo.get(1) is None and memo.misses == 1


def test_a_memo_holds_at_least_one_answer() -> None:
    with pytest.raises(ValueError):
        Memo(0)


def test_clear_caches_empties_every_memo() -> None:
    memos = [Memo[int, int](8) for _ in range(3)]
    for memo in memos:
        memo.put(1, 1)
        assert memo.get(1) == 1
    clear_caches()
    assert [(len(m), m.hits, m.get(1)) for m in memos] == [(0, 0, None)] * 3
    memos[0].put(2, 2)                     # in use again after the clear
    assert memos[0].get(2) == 2


def _looping(motors: int = 2) -> Chain:
    chain = Chain(motors=motors)
    for n in range(1, motors + 1):
        for line in (f"S1.{n}=100, A1.{n}=100, P1.{n}=10000, P2.{n}=0", f"B1.{n}", "X0",
                     f"S1.{n}, A1.{n}, P1.{n}", f"P2.{n}", "X-", "END"):
            chain.execute(line)
        chain.execute(f"[1.{n}")
    return chain


def test_a_chain_has_its_own_memos_shared_by_its_motors() -> None:
    """Two chains share nothing; the alike motors of one chain reuse each other's
    solutions (motor 2 moves as motor 1 does: its moves are found solved)."""
    first, second = _looping(), Chain(motors=2)
    other = second.motion_memos
    untouched = (len(other.plans), len(other.placed), other.reuse())   # its holds at 0
    first.kernel.run(until=seconds(12))
    memos = first.motion_memos
    assert all(m.axis.memos is memos for m in first.motors.values())
    assert len(memos.plans) > 0 and len(memos.placed) > 0
    reused, solved = memos.reuse()
    assert reused > solved > 0
    assert other is not memos
    assert (len(other.plans), len(other.placed), other.reuse()) == untouched


def test_clear_caches_reaches_a_chains_memos_and_the_motion_goes_on_the_same() -> None:
    kept, cleared = _looping(1), _looping(1)
    for chain in (kept, cleared):
        chain.kernel.run(until=seconds(5))
    assert len(cleared.motion_memos.placed) > 0
    clear_caches()
    assert len(cleared.motion_memos.placed) == 0
    for chain in (kept, cleared):
        chain.kernel.run(until=seconds(30))
    assert kept.motors[1].axis.raw_actual() == cleared.motors[1].axis.raw_actual()
    assert cleared.motion_memos.reuse()[0] > 0     # remembered again since


def test_a_remembered_solution_is_handed_out_immutable() -> None:
    chain = _looping(1)
    chain.kernel.run(until=seconds(5))
    motion = chain.motors[1].axis.motion
    assert isinstance(motion.pieces, tuple)
    assert isinstance(motion._starts, tuple)
    assert isinstance(motion.profile.segments, tuple)
