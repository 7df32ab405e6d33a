"""Test-wide settings.

Hypothesis explores new random examples on every local run (and keeps the failures it
finds in .hypothesis/); under CI (``CI`` set) it draws a fixed sequence, so the suite is
the same every run there, as the rest of it is in virtual time.

Tests marked ``realtime`` run SCHED_FIFO threads (EtherCAT masters under ``chrt``,
the bridge's frame thread, the EtherNet/IP producer) or measure wall-clock timing.
Run side by side on two cores, one test's real-time master could starve another's
real-time producer, so under pytest-xdist (``--dist loadgroup``, scripts/test) they
all go to one worker, one after the other.

The shared fixtures (what they build is in tests/fixtures.py, plain Python):

``make_chain``
    builds chains (``make_chain(motors=2, firmware="rt3", state_dir=..., machine=...,
    plant={...}, setup="K23.1=17")``) and closes them (their stores) after the test;
    ``chain`` is one default chain (one CM2, no state).
``served_sim``
    starts ``coolmuscle sim`` processes on free ports and waits for their banners
    (``served_sim(tcp=True, modbus_tcp=False, pty=False, state=None, *args)``); every
    one still running is killed with its process group after the test, passed or not.
``closed_port``
    a TCP port that refuses connections during the test.

``wait_until``, ``free_port`` and ``coolmuscle_env`` are functions: import them from
``fixtures``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import pytest
from hypothesis import settings

if TYPE_CHECKING:       # imported when a fixture is used: this file loads nothing else
    from coolmuscle.chain.daisy import Chain
    from fixtures import ChainFactory, ServedSim, SimFactory

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.hookimpl(tryfirst=True)    # before xdist's own hook reads the groups (loadgroup)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.get_closest_marker("realtime") is not None:
            item.add_marker(pytest.mark.xdist_group("realtime"))


@pytest.fixture
def make_chain() -> Iterator[ChainFactory]:
    """``make_chain(**options)``: :func:`fixtures.new_chain`, closed after the test."""
    from fixtures import new_chain
    made: list[Chain] = []

    def make(*args: Any, **options: Any) -> Chain:
        made.append(new_chain(*args, **options))
        return made[-1]
    yield make
    for chain in made:
        chain.close()


@pytest.fixture
def chain(make_chain: ChainFactory) -> Chain:
    """One CM2 on its own, no state."""
    return make_chain()


@pytest.fixture
def served_sim(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SimFactory]:
    """``served_sim(*args, tcp=True, modbus_tcp=False, pty=False, state=None)``: a ready
    ``coolmuscle sim`` (:class:`fixtures.ServedSim`); none is left running after the
    test."""
    from fixtures import ServedSim
    started: list[ServedSim] = []
    logs = tmp_path_factory.mktemp("sim")

    def start(*args: str, **options: Any) -> ServedSim:
        log = logs / f"sim{len(started)}.log"
        sim = ServedSim(log, *args, **options)
        started.append(sim)
        return sim
    yield start
    for sim in reversed(started):
        sim.close()


@pytest.fixture
def closed_port() -> Iterator[int]:
    """A TCP port on 127.0.0.1 that refuses connections while the test runs."""
    from fixtures import closed_port
    with closed_port() as port:
        yield port
