"""The EtherCAT bridge for a master in the test (``cm_lab``: as root, or without root inside
``coolmuscle ethercat lab run --no-sim -- pytest``; else skipped with the reason)."""

from __future__ import annotations

import pytest


def test_an_ethercat_master_finds_the_bridge(cm_lab):
    pysoem = pytest.importorskip("pysoem")
    master = pysoem.Master()
    master.open(cm_lab.master_if)
    try:
        assert master.config_init() == 1
    finally:
        master.close()
