"""Bounded memos: the one way the model remembers answers it has computed.

A :class:`Memo` keeps at most ``size`` answers by key.  When it is full, a new answer
replaces the *oldest* one put (first in, first out): a machine that repeats a cycle
finds its answers again and a hit moves nothing, while a stream of new keys (a csp
target every cycle) pushes the old ones out one at a time; nothing is flushed all at
once.  :func:`clear_caches` makes every memo of the process forget everything (each
empties itself at its next use), for benchmarks that time work done afresh and tests
that compare a fresh computation with a remembered one.

The rules (docs/architecture.md "Fast code"): a memo belongs to the object whose state
its answers depend on (a chain, a motor), never to the module; its keys are plain
values (numbers, strings, tuples of them; a version stamp where the answer depends on
K parameters or banks); its answers are immutable (tuples, frozen or
immutable-by-convention objects), so a hit and a miss hand out the same value and
nobody can change what another will be given.  A memo is used by the one thread that
runs its chain.

This module imports nothing from coolmuscle: it is the bottom of the layering, and it
is compiled with the hot modules (coolmuscle/_accel.py), so the compiled model calls
:meth:`Memo.get` directly.
"""

from __future__ import annotations

from typing import Final, Generic, TypeVar

K = TypeVar("K")
V = TypeVar("V")


class _Generation:
    """How many times :func:`clear_caches` has run; each memo keeps the count it has seen."""

    def __init__(self) -> None:
        self.count = 0


_GENERATION: Final = _Generation()


def clear_caches() -> None:
    """Forget every answer of every :class:`Memo` (every chain's, every motor's)."""
    _GENERATION.count += 1


class Memo(Generic[K, V]):
    """At most ``size`` answers by key; when full, the oldest answer put makes room.

    ``get`` answers ``None`` for a key it does not hold, so an answer is never ``None``.
    ``hits`` and ``misses`` count the ``get`` calls since the last :meth:`clear`."""

    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError(f"a memo holds at least one answer, not {size}")
        self.size = size
        self.hits = 0
        self.misses = 0
        self._answers: dict[K, V] = {}
        #: The keys in the order they were put, a ring once full: ``_oldest`` is the next
        #: to go (no scan of the dict for its first key: that walks the holes deletions
        #: leave at its front).
        self._order: list[K] = []
        self._oldest = 0
        self._generation = _GENERATION.count

    def get(self, key: K) -> V | None:
        """The answer kept for ``key``, or ``None``."""
        if self._generation != _GENERATION.count:
            self.clear()
        found = self._answers.get(key)
        if found is None:
            self.misses += 1
        else:
            self.hits += 1
        return found

    def put(self, key: K, answer: V) -> V:
        """Keep ``answer`` for ``key`` (the oldest answer goes when the memo is full);
        returns ``answer``."""
        answers = self._answers
        if key not in answers:
            order = self._order
            if len(order) < self.size:
                order.append(key)
            else:
                oldest = self._oldest
                del answers[order[oldest]]
                order[oldest] = key
                self._oldest = oldest + 1 if oldest + 1 < self.size else 0
        answers[key] = answer
        return answer

    def clear(self) -> None:
        """Forget every answer and the counts."""
        self._answers.clear()
        self._order.clear()
        self._oldest = 0
        self.hits = 0
        self.misses = 0
        self._generation = _GENERATION.count

    def __len__(self) -> int:
        if self._generation != _GENERATION.count:
            self.clear()
        return len(self._answers)

    def __repr__(self) -> str:
        return f"Memo(size={self.size}, held={len(self)}, hits={self.hits}, misses={self.misses})"
