"""KickCAT (a second, independent master: its own C++ stack) against the bridge.

Manual 5.2 (INIT to OP), 6.3.1 (24-byte images each way).
"""

from __future__ import annotations

import struct

import pytest

from coolmuscle.frontends.ethercat.bridge.app import BridgeApp
from coolmuscle.frontends.ethercat.engine import esm
from ethercat_support import link, needs_net_admin, run_master, serving

pytest.importorskip("kickcat")
pytestmark = [needs_net_admin, pytest.mark.realtime]


def test_kickcat_reaches_op_and_exchanges_process_data_5_2_6_3_1():
    app = BridgeApp(None)
    od = app.dictionary
    for axis in range(4):                      # an input image the master must see
        od.set(0x6041 + 0x800 * axis, 0, 0x0250 + axis)
        od.set(0x6064 + 0x800 * axis, 0, -1000 * (axis + 1))
    app.stack.set_inputs(od.pack_inputs())
    with link("k1") as lab, serving(app.stack.esc, lab.slave_if):
        r = run_master(lab, "kickcat_master.py", "300")
    assert r["found"] == 1
    assert r["sdo_1008"] == "EB02 CM2 EtherCAT Cool MUSCLE Bridge"
    assert (r["in_size"], r["out_size"]) == (24, 24)
    assert r["safeop"].endswith("SAFE_OP") and r["op"].endswith("OPERATIONAL")
    assert r["errors"] <= 1
    expected = b"".join(struct.pack("<Hi", 0x0250 + a, -1000 * (a + 1)) for a in range(4))
    assert bytes.fromhex(r["last_input"]) == expected
    assert od.get(0x6040, 0) == 0x0006 and od.get(0x607A, 0) == r["last_target"]
    assert r["init"].endswith("INIT")
    assert (esm.SAFEOP, esm.OP, 0) in app.stack.transitions
