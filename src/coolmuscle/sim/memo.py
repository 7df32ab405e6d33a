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

This module imports nothing from coolmuscle: it sits with the kernel at the bottom of
the layering, below every user, and it is compiled with the hot modules
(coolmuscle/_accel.py), so the compiled model calls :meth:`Memo.get` directly.
"""

from __future__ import annotations

from typing import Final, Generic, TypeVar

K = TypeVar("K")
V = TypeVar("V")

#: The type of a memo's key made of several values: a plain tuple.  In compiled code a
#: tuple of fixed size is kept unboxed and boxed anew at every call, so a key typed so
#: would reach ``get`` and ``put`` as two objects and be hashed twice (``put`` reuses the
#: hash ``get`` computed only for the very object it was asked).
Key = tuple[object, ...]


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
    ``hits`` and ``misses`` count the ``get`` calls since the last :meth:`clear`.

    A key is hashed once.  The model's keys are tuples of floats, whose hash Python
    does not keep and which costs as much as the rest of a lookup; a miss is a ``get``,
    a ``put`` and, once full, the removal of the oldest answer.  So the answers are
    kept by the hash of their key (the key beside the answer, compared on a hit), a
    ``put`` of the key object the last ``get`` missed uses the hash ``get`` computed
    (a key of several values is a :data:`Key`, so that it stays one object), and
    the oldest answer goes by its hash (a ring of hashes, in the order they came).  Two
    keys of one hash share a place: the one put later replaces the other, which is
    then a miss, never a wrong answer."""

    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError(f"a memo holds at least one answer, not {size}")
        self.size = size
        self.hits = 0
        self.misses = 0
        self._answers: dict[int, tuple[K, V]] = {}
        self._order: list[int] = []         # the hashes as they came; a ring once full
        self._oldest = 0                    # where the ring's oldest hash is
        self._asked: object = None          # the key of the last get missed, its hash
        self._asked_hash = 0
        self._generation = _GENERATION.count

    def get(self, key: K) -> V | None:
        """The answer kept for ``key``, or ``None``."""
        if self._generation != _GENERATION.count:
            self.clear()
        h = hash(key)
        found = self._answers.get(h)
        if found is not None:
            kept = found[0]
            if kept is key or kept == key:
                self.hits += 1
                return found[1]
        self._asked = key                   # the put that follows a miss needs the hash
        self._asked_hash = h
        self.misses += 1
        return None

    def put(self, key: K, answer: V) -> V:
        """Keep ``answer`` for ``key`` (the oldest answer goes when the memo is full);
        returns ``answer``."""
        h = self._asked_hash if key is self._asked else hash(key)
        answers = self._answers
        held = len(answers)
        answers[h] = (key, answer)
        if len(answers) != held:            # a new place, not a key put again
            order = self._order
            if len(order) < self.size:
                order.append(h)
            else:
                oldest = self._oldest
                del answers[order[oldest]]
                order[oldest] = h
                self._oldest = oldest + 1 if oldest + 1 < self.size else 0
        return answer

    def clear(self) -> None:
        """Forget every answer and the counts."""
        self._answers.clear()
        self._order.clear()
        self._oldest = 0
        self._asked = None
        self.hits = 0
        self.misses = 0
        self._generation = _GENERATION.count

    def __len__(self) -> int:
        if self._generation != _GENERATION.count:
            self.clear()
        return len(self._answers)

    def __repr__(self) -> str:
        return f"Memo(size={self.size}, held={len(self)}, hits={self.hits}, misses={self.misses})"
