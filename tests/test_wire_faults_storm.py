"""Fuzz-level robustness with wire faults on (docs/wire-faults.md, docs/reliability.md):
a bounded version of bench/bench_wirefaults.py's storm.  For 20 s faults of every door
rain on a served chain (TCP host line, Modbus TCP, the CM1 EtherNet/IP module) while the
host library, pymodbus and pycomm3 keep talking to it and motor 2 is saved and power
cycled over and over: no traceback, no peer failing other than with its typed errors,
no saved data lost (after every power-up and in the store at the end), and resident
memory flat from the first sample on.
"""

from __future__ import annotations

import pytest

from storm_support import storm

pytestmark = [pytest.mark.peer, pytest.mark.realtime]


def test_a_fault_storm_leaves_no_traceback_no_lost_save_and_flat_memory():
    report = storm(20.0, samples=4)
    assert report.clean, report.summary() + "\n" + "\n".join(report.problems())
    assert report.faults > 100 and report.power_cycles > 20, report.summary()
    assert all(report.exchanges.get(peer, 0) > 50 for peer in ("host", "modbus", "enip")), \
        report.summary()
    assert sum(report.typed_errors.values()) > 0, report.summary()    # faults did bite
    first, last = report.rss[1][1], report.rss[-1][1]
    assert last - first < 4.0, report.summary()                          # MiB
