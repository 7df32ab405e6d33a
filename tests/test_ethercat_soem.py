"""SOEM (pysoem) as the master of the bridge over a veth pair: a real master's view.

Manual sections: 5.2 (ESM, AL status codes), 5.4.1 (abort codes), 6.3.1/6.3.3
(24-byte csp images), Appendix 6 (1000h, 1008h, 1018h).
"""

from __future__ import annotations

import struct

import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.ethercat.bridge import identity as ident
from coolmuscle.frontends.ethercat.bridge.app import BridgeApp
from coolmuscle.frontends.ethercat.engine import esm
from coolmuscle.frontends.ethercat.transport import EthercatTransport
from coolmuscle.frontends.transports.service import ServiceThread
from ethercat_support import link, needs_net_admin, run_master, serving

pytestmark = [needs_net_admin, pytest.mark.realtime]


def test_soem_scans_reads_maps_and_runs_10000_cycles_5_2_5_4_6_3():
    with link("s1") as lab:
        with ServiceThread(lambda: Chain(None, 4, firmware="cm2"),
                           lambda: [EthercatTransport(lab.slave_if, "EB02")]) as st:
            st.call(lambda: st.chain.execute("K37.1=1"))
            r = run_master(lab, "soem_master.py", "full", "10000", timeout=110)
            transport = st.transports[0]
            od = transport.app.dictionary
            last_target = od.get(0x607A, 0)
            stack = transport.app.stack
            transitions = list(stack.transitions)
    assert r["found"] == 1
    assert r["name"] == "EB02 CM2 EtherCAT Cool MUSCLE Bridge"
    assert (r["vendor"], r["product"], r["revision"]) == (ident.VENDOR_ID, 0x00EB0002,
                                                          ident.REVISION)
    assert r["sdo_1000"] == struct.pack("<I", 0x00040192).hex()
    assert r["sdo_1008"] == "EB02 CM2 EtherCAT Cool MUSCLE Bridge"
    assert r["sdo_1018"] == [ident.VENDOR_ID, 0x00EB0002, ident.REVISION, ident.SERIAL]
    assert r["sdo_1018_0"] == 4
    assert r["abort_absent"] == 0x06020000
    assert r["abort_read_only"] == 0x06010002
    assert r["abort_subindex"] == 0x06090011
    assert r["od_1018"] == [["Identity", ["Number of entries", "Vendor ID", "Product code",
                                          "Revision", "Serial number"]]], r["od_1018"]
    assert r["od_count"] > 50
    assert (r["out_len"], r["in_len"]) == (24, 24)
    assert r["safeop"] == 4 and r["op"] == 8 and r["expected_wkc"] == 3
    assert r["wkc_ok"] >= 0.999 * r["cycles"], (r["wkc_ok"], r["missed"])
    assert last_target == r["cycles"] - 1        # the last output image reached the dictionary
    assert r["init"] == 1
    assert (esm.SAFEOP, esm.OP, 0) in transitions and (esm.OP, esm.INIT, 0) in transitions
    assert len(bytes.fromhex(r["last_input"])) == 24


def test_soem_init_to_op_is_refused_with_0011_and_the_error_bit_5_2_2():
    app = BridgeApp(None)
    with link("s2") as lab, serving(app.stack.esc, lab.slave_if):
        r = run_master(lab, "soem_master.py", "invalid")
    assert r["init"] == 1
    assert r["after_op_request"] == esm.INIT | esm.ERROR_FLAG
    assert r["al_status_code"] == 0x0011
    assert r["after_ack"] == esm.INIT
    assert r["code_after_ack"] == 0


def test_soem_silent_master_trips_the_sm_watchdog_into_safeop_001b_5_2_2():
    app = BridgeApp(None)
    with link("s3") as lab, serving(app.stack.esc, lab.slave_if):
        r = run_master(lab, "soem_master.py", "watchdog")
    assert r["op"] == 8 and r["wkc_ok"] >= 99
    assert r["after_silence"] == esm.SAFEOP | esm.ERROR_FLAG
    assert r["al_status_code"] == 0x001B
    assert app.stack.state == esm.SAFEOP


def test_soem_reaches_op_after_a_master_pointed_the_read_mailbox_at_the_registers_5_2_2():
    """A master rewrites SM1 in PRE-OP to AL status (0x0130): in place (the ESC keeps an
    activated SyncManager's settings: SDO still works), then deactivated and activated
    there (the ESC does not activate it outside the process RAM; the slave goes to
    INIT with 0016h).  AL status stays a state throughout; a fresh SOEM master then
    scans, maps and runs cycles in OP."""
    app = BridgeApp(None)
    with link("s4") as lab, serving(app.stack.esc, lab.slave_if):
        bad = run_master(lab, "soem_master.py", "misconfigure")
        try:
            fresh = run_master(lab, "soem_master.py", "full", "200")
        except AssertionError as exc:
            raise AssertionError(f"a fresh master fails after {bad}") from exc
    assert fresh["found"] == 1 and fresh["safeop"] == esm.SAFEOP and fresh["op"] == esm.OP
    assert fresh["wkc_ok"] >= 0.99 * fresh["cycles"]
    assert fresh["init"] == esm.INIT
    assert app.stack.esc.al_status == esm.INIT
    sm1 = f"{ident.MBX_IN_START:04x}"
    assert bad["preop"] == esm.PREOP
    assert bad["in_place_sm1"][:4] == bytes.fromhex(sm1)[::-1].hex()   # kept at 0x1080
    assert bad["in_place_sdo"] == struct.pack("<I", ident.VENDOR_ID).hex()
    assert bad["in_place_al"] == [esm.PREOP, 0]
    assert bad["deactivated_al"] == [esm.INIT | esm.ERROR_FLAG, 0x0016]
    assert bad["pointed_sm1"] == "3001800022000000"                   # not activated
    assert bad["pointed_sdo"] != struct.pack("<I", ident.VENDOR_ID).hex()
    assert bad["pointed_al"] == [esm.INIT | esm.ERROR_FLAG, 0x0016]
