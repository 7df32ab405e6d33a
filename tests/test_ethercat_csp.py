"""The CiA402 drive in csp behind the bridge (manual 6.1-6.3), driven by SOEM (pysoem).

Part 2's first piece: the state machine of 6.1.1 with the controlwords of 6.1.2 and
the statuswords of 6.1.3, and csp following 607Ah through ``Device.target_stream``.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.ethercat.bridge import cia402
from coolmuscle.frontends.ethercat.bridge.cia402 import State
from coolmuscle.frontends.ethercat.transport import EthercatTransport
from coolmuscle.frontends.transports.service import ServiceThread
from ethercat_support import MASTERS, link, needs_net_admin, run_master

pytestmark = pytest.mark.realtime


def test_cia402_table_6_1_1_transitions():
    s = State.NOT_READY
    s = cia402.next_state(s, 0, 0, False)
    assert s is State.SWITCH_ON_DISABLED
    for cw, want in ((0x06, State.READY), (0x07, State.SWITCHED_ON),
                     (0x0F, State.OPERATION_ENABLED), (0x07, State.SWITCHED_ON),
                     (0x0F, State.OPERATION_ENABLED), (0x02, State.OPERATION_ENABLED),
                     (0x06, State.READY), (0x0F, State.OPERATION_ENABLED),
                     (0x00, State.SWITCH_ON_DISABLED)):
        s = cia402.next_state(s, cw, 0, False)
        assert s is want, (hex(cw), s)
    s = cia402.next_state(State.OPERATION_ENABLED, 0x0F, 0x0F, True)
    assert s is State.FAULT_REACTION
    s = cia402.next_state(s, 0x0F, 0x0F, True)
    assert s is State.FAULT
    assert cia402.next_state(s, 0x80, 0x80, True) is State.FAULT           # no rising edge
    s = cia402.next_state(s, 0x80, 0x00, True)                             # 15: reset
    assert s is State.SWITCH_ON_DISABLED
    s = cia402.next_state(s, 0x06, 0x80, True)           # State A: the latched alarm waits
    assert s is State.READY
    assert cia402.next_state(s, 0x07, 0x06, True) is State.SWITCHED_ON


def test_statusword_6_1_3():
    assert cia402.statusword(State.SWITCH_ON_DISABLED, csp=True, alarm=False, free=True) \
        == 0x8240
    assert cia402.statusword(State.OPERATION_ENABLED, csp=True, alarm=False, free=False) \
        == 0x1227
    assert cia402.statusword(State.FAULT, csp=True, alarm=True, free=True) == 0xC208


@needs_net_admin
def test_soem_enables_all_axes_and_a_2s_csp_ramp_ends_on_target_6_3():
    with link("c1") as lab:
        with ServiceThread(lambda: Chain(None, 4, firmware="cm2"),
                           lambda: [EthercatTransport(lab.slave_if, "EB02")]) as st:
            r = run_master(lab, "soem_master.py", "csp", timeout=110)
            positions = [st.call(lambda a=a: st.chain.snapshot(a).position) for a in range(1, 5)]
    assert r["op"] == 8
    assert all(w & 0x6F == 0x21 for w in r["words"]["0x6"]), r["words"]
    assert all(w & 0x6F == 0x23 for w in r["words"]["0x7"]), r["words"]
    assert all(w & 0x6F == 0x27 and w & 0x1000 and not w & 0xC000
               for w in r["words"]["0xf"]), r["words"]
    for final, target, actual in zip(r["final"], r["targets"], positions):
        assert abs(final - target) <= 10, (r["final"], r["targets"])
        assert abs(actual - target) <= 10
    assert r["targets"] == [p + 4000 for p in r["start"]]
    assert r["max_lag"] < 100, r["max_lag"]       # 2 pulses/ms: a few cycles of lag at most
    assert all(w & 0x6F == 0x21 and w & 0x8000 for w in r["after_shutdown"]), \
        r["after_shutdown"]


@needs_net_admin
def test_a_motor_alarm_is_a_fault_and_fault_reset_clears_it_6_1_1():
    with link("c2") as lab:
        with ServiceThread(lambda: Chain(None, 4, firmware="cm2"),
                           lambda: [EthercatTransport(lab.slave_if, "EB02")]) as st:
            master = subprocess.Popen(
                ["ip", "netns", "exec", lab.namespace, sys.executable,
                 str(MASTERS / "soem_master.py"), lab.master_if, "fault"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            try:
                assert master.stdout.readline().strip() == "READY"
                st.call(lambda: st.chain.inject_fault(2, "over_current"))
                out, err = master.communicate("go\n", timeout=60)
            finally:
                if master.poll() is None:
                    master.kill()
    r = json.loads(out.strip().splitlines()[-1])
    assert all(w & 0x6F == 0x27 for w in r["enabled"]), r["enabled"]
    faulted = r["faulted"]
    assert faulted[1] & 0x4F == 0x08 and faulted[1] & 0x4000, hex(faulted[1])   # ID2: Fault
    assert all(w & 0x6F == 0x27 for i, w in enumerate(faulted) if i != 1)
    assert r["after_0x80"][1] & 0x4F == 0x40                   # fault reset: switch on disabled
    assert r["after_0x0f"][1] & 0x6F == 0x27 and not r["after_0x0f"][1] & 0x4000, \
        [hex(w) for w in r["after_0x0f"]]
