"""Test-wide settings.

Hypothesis explores new random examples on every local run (and keeps the failures it
finds in .hypothesis/); under CI (``CI`` set) it draws a fixed sequence, so the suite is
the same every run there, as the rest of it is in virtual time.

Tests marked ``realtime`` run SCHED_FIFO threads (EtherCAT masters under ``chrt``,
the bridge's frame thread, the EtherNet/IP producer) or measure wall-clock timing.
Run side by side on two cores, one test's real-time master could starve another's
real-time producer, so under pytest-xdist (``--dist loadgroup``, scripts/test) they
all go to one worker, one after the other.
"""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.hookimpl(tryfirst=True)    # before xdist's own hook reads the groups (loadgroup)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.get_closest_marker("realtime") is not None:
            item.add_marker(pytest.mark.xdist_group("realtime"))
