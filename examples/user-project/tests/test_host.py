"""The host program against a virtual motor: in virtual time on the test's chain, and in
real time on a served simulator over TCP (as it would talk to a real motor's port)."""

from __future__ import annotations

import urllib.request

import pytest
from conveyor import host


def test_a_cycle_in_virtual_time(cm_chain):
    port = cm_chain.port()
    host.load(port)
    assert host.run_cycle(port) >= host.PLACE - 10
    cm_chain.expect(1).no_alarm()
    cm_chain.expect(1).position(host.PLACE, within=2, by=cm_chain.now)


@pytest.mark.cm_sim(web=True)
def test_a_cycle_on_a_served_simulator(cm_sim):
    host.load(cm_sim.url)
    assert host.run_cycle(cm_sim.url) >= host.PLACE - 10
    with urllib.request.urlopen(cm_sim.web_url, timeout=10) as page:   # its dashboard
        assert page.status == 200
