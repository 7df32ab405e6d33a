"""The chain's bank waits (cml-users-guide.txt 2.2 "W", program lines waiting for
motions): ``ChainBus.watch`` / ``ChainBus.poke`` (a chain's ``bus``) call every watcher
concerned, once, in the order the watchers came, whatever is added or removed on the way."""

from __future__ import annotations

from collections.abc import Callable

from hypothesis import given, settings
from hypothesis import strategies as st

from coolmuscle.chain.daisy import Chain
from fixtures import ChainFactory

MOTORS = (1, 2, 3)

# An operation: ("watch", motors or None), ("remove", k), ("poke", motor or None),
# ("poke-removing", motor or None, k): a poke whose first watcher removes watcher k.
ops = st.lists(st.one_of(
    st.tuples(st.just("watch"), st.none() | st.lists(st.sampled_from(MOTORS), max_size=3)),
    st.tuples(st.just("remove"), st.integers(0, 12)),
    st.tuples(st.just("poke"), st.none() | st.sampled_from(MOTORS)),
    st.tuples(st.just("poke-removing"), st.none() | st.sampled_from(MOTORS),
              st.integers(0, 12)),
), max_size=40)


class Reference:
    """The rule written plainly: every watcher at each poke, in order, from a copy."""

    def __init__(self) -> None:
        self.entries: list[tuple[int, frozenset[int] | None]] = []

    def watch(self, n: int, motors: list[int] | None) -> Callable[[], None]:
        entry = (n, None if motors is None else frozenset(motors))
        self.entries.append(entry)

        def remove() -> None:
            if entry in self.entries:
                self.entries.remove(entry)
        return remove

    def poke(self, motor: int | None) -> list[int]:
        return [n for n, ms in list(self.entries)
                if ms is None or motor is None or motor in ms]


@settings(max_examples=150, deadline=None)
@given(ops)
def test_poke_calls_the_watchers_concerned_in_order(operations: list[tuple]) -> None:
    chain = Chain(motors=len(MOTORS))
    ref = Reference()
    calls: list[int] = []
    removers: list[Callable[[], None]] = []
    ref_removers: list[Callable[[], None]] = []
    pending: list[int] = []              # the watcher the next poke's first call removes

    def watcher(n: int) -> Callable[[], None]:
        def call() -> None:
            calls.append(n)
            if pending:
                removers[pending.pop()]()
        return call

    for op in operations:
        if op[0] == "watch":
            n = len(removers)
            removers.append(chain.bus.watch(watcher(n), op[1]))
            ref_removers.append(ref.watch(n, op[1]))
        elif op[0] == "remove":
            if op[1] < len(removers):
                removers[op[1]]()
                ref_removers[op[1]]()
        else:
            calls.clear()
            expected = ref.poke(op[1])
            if op[0] == "poke-removing" and op[2] < len(removers) and expected:
                pending.append(op[2])
                chain.bus.poke(op[1])
                ref_removers[op[2]]()
            else:
                chain.bus.poke(op[1])
            pending.clear()
            assert calls == expected
    chain.close()


def test_a_watcher_removed_during_a_poke_still_runs_in_that_poke(make_chain: ChainFactory) -> None:
    chain = make_chain(motors=2)
    calls: list[str] = []
    removers: dict[str, Callable[[], None]] = {}

    def first() -> None:
        calls.append("first")
        removers["second"]()

    removers["first"] = chain.bus.watch(first, [1])
    removers["second"] = chain.bus.watch(lambda: calls.append("second"), [1, 2])
    removers["third"] = chain.bus.watch(lambda: calls.append("third"), [1])
    chain.bus.watch(lambda: calls.append("other"), [2])
    chain.bus.poke(1)
    assert calls == ["first", "second", "third"]
    calls.clear()
    chain.bus.poke(1)
    assert calls == ["first", "third"]
    calls.clear()
    chain.bus.poke(2)
    assert calls == ["other"]
    calls.clear()
    chain.bus.poke()                        # about nothing in particular: every watcher
    assert calls == ["first", "third", "other"]
    chain.close()
