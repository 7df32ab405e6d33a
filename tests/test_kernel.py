"""The simulation kernel's shared events (:meth:`Kernel.schedule_shared`): the axes of a
fieldbus cycle waiting for the same instant cost one event (docs/performance.md)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from coolmuscle.sim.kernel import PRIO_HORIZON, PRIO_MOTION, Kernel, ms, nearest, seconds


def test_callbacks_shared_by_an_instant_run_in_one_event_in_the_order_given() -> None:
    kernel = Kernel()
    ran: list[tuple[str, int]] = []
    for name in "abc":
        kernel.schedule_shared(1_000, lambda n=name: ran.append((n, kernel.now)),
                               priority=PRIO_HORIZON)
    assert kernel.run(until=2_000) == 1
    assert ran == [("a", 1_000), ("b", 1_000), ("c", 1_000)]


def test_shared_callbacks_keep_their_place_among_the_priorities_of_their_instant() -> None:
    kernel = Kernel()
    ran: list[str] = []
    kernel.schedule_at(500, lambda: ran.append("motion"), priority=PRIO_MOTION)
    kernel.schedule_shared(500, lambda: ran.append("horizon 1"), priority=PRIO_HORIZON)
    kernel.schedule_at(500, lambda: ran.append("io"), priority=0)
    kernel.schedule_shared(500, lambda: ran.append("horizon 2"), priority=PRIO_HORIZON)
    kernel.schedule_shared(500, lambda: ran.append("motion shared"), priority=PRIO_MOTION)
    kernel.run(until=500)
    assert ran == ["io", "horizon 1", "horizon 2", "motion", "motion shared"]


def test_one_given_while_its_instant_runs_gets_an_event_of_its_own_after_it() -> None:
    kernel = Kernel()
    ran: list[str] = []

    def first() -> None:
        ran.append("first")
        kernel.schedule_shared(kernel.now, lambda: ran.append("again"),
                               priority=PRIO_HORIZON)
    kernel.schedule_shared(100, first, priority=PRIO_HORIZON)
    kernel.schedule_shared(100, lambda: ran.append("second"), priority=PRIO_HORIZON)
    assert kernel.run(until=100) == 2
    assert ran == ["first", "second", "again"]


def test_an_instant_in_the_past_is_now() -> None:
    kernel = Kernel(start=5_000)
    ran: list[int] = []
    kernel.schedule_shared(10, lambda: ran.append(kernel.now), priority=PRIO_HORIZON)
    kernel.schedule_shared(5_000, lambda: ran.append(kernel.now), priority=PRIO_HORIZON)
    assert kernel.run(until=5_000) == 1
    assert ran == [5_000, 5_000]


def test_a_callback_that_fails_leaves_the_others_of_its_instant_to_run() -> None:
    """A failure propagates out of the run, as any event's; the callbacks after it in
    the shared event run when the kernel runs again, as they would with an event each."""
    kernel = Kernel()
    ran: list[str] = []

    def fails() -> None:
        raise RuntimeError("model bug")
    kernel.schedule_shared(100, lambda: ran.append("before"), priority=PRIO_HORIZON)
    kernel.schedule_shared(100, fails, priority=PRIO_HORIZON)
    kernel.schedule_shared(100, lambda: ran.append("after 1"), priority=PRIO_HORIZON)
    kernel.schedule_shared(100, lambda: ran.append("after 2"), priority=PRIO_HORIZON)
    with pytest.raises(RuntimeError):
        kernel.run(until=200)
    assert ran == ["before"] and kernel.now == 100
    kernel.run(until=200)
    assert ran == ["before", "after 1", "after 2"] and kernel.now == 200


@given(st.floats(allow_nan=False, allow_infinity=False)
       | st.integers(-10**15, 10**15).map(lambda n: n + 0.5)
       | st.floats(-4.0, 4.0))
def test_nearest_is_round_to_the_bit_ties_to_even(x: float) -> None:
    """Kernel times are rounded with ``nearest`` (compiled code's own arithmetic): the
    same integer as ``round``, a tie to the even one, huge values included."""
    assert nearest(x) == round(x)
    assert seconds(x / 1e9) == round(x / 1e9 * 1e9)


def test_nearest_refuses_what_round_refuses() -> None:
    for bad, error in ((math.inf, OverflowError), (-math.inf, OverflowError),
                       (math.nan, ValueError)):
        with pytest.raises(error):
            round(bad)
        with pytest.raises(error):
            nearest(bad)


def test_seconds_and_ms_round_ties_to_even() -> None:
    assert seconds(2.5e-9) == 2 and seconds(3.5e-9) == 4 and seconds(-2.5e-9) == -2
    assert ms(0.0000025) == 2 and ms(1.5) == 1_500_000
