"""Three bridges in a line (EB02, EB12, EB01) under real masters: pysoem and KickCAT.

The bridges run in this process (one kernel, a chain of four motors each) behind one
veth end; each master runs in its own namespace on the other end.  Manual 1.3/1.4 (the
variants), 5.2 (ESM), 6.1.2/6.3 (csp), 7.5 (60F6h: K parameters), 8.1.4 (the ESI).
"""

from __future__ import annotations

import json
import subprocess
import xml.etree.ElementTree as ET

import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.ethercat.bridge import identity as ident
from coolmuscle.frontends.ethercat.bridge.esi import esi_text
from coolmuscle.frontends.ethercat.engine import esm
from coolmuscle.frontends.ethercat.transport import EthercatTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.sim.kernel import Kernel
from ethercat_support import link, master_command, needs_net_admin, run_master

pytestmark = [needs_net_admin, pytest.mark.realtime]

CODES = ("EB02", "EB12", "EB01")
#: The axis (0-3) that moves on each bridge: EB02 ID1 (CM2), EB12 ID3 (CM2), EB01 ID2 (CM1).
MOVING = (0, 2, 1)
K43_DEFAULT, K43_WRITTEN = 100, 150
#: DL status of an ESC whose port 1 has no link (the loop closed there).
PORT1_CLOSED = 0x5613


def bridge_chain(kernel: Kernel, _position: int, firmware: str) -> Chain:
    return Chain(kernel, 4, firmware=firmware)


def segment_service(iface: str) -> ServiceThread:
    return ServiceThread(lambda: Chain(None, 4, firmware="cm2"),
                         lambda: [EthercatTransport(iface, bridges=CODES, chains=bridge_chain)])


def esi_devices() -> dict[str, tuple[str, int, int]]:
    """Each variant's (name, product code, revision) as its ESI file gives them."""
    root = ET.fromstring(esi_text(CODES).split("\n", 1)[1])
    out = {}
    for device in root.iter("Device"):
        kind = device.find("Type")
        assert kind is not None and kind.text is not None
        out[kind.text] = (device.findtext("Name") or "", int(kind.get("ProductCode", "")[2:], 16),
                          int(kind.get("RevisionNo", "")[2:], 16))
    return out


def _line(proc: subprocess.Popen[str]) -> str:
    assert proc.stdout is not None
    line = proc.stdout.readline().strip()
    if line != "READY":
        proc.kill()
        raise AssertionError(f"the master said {line!r}: {proc.communicate()[1][-3000:]}")
    return line


def test_soem_three_bridges_to_op_csp_on_each_an_sdo_to_the_second_unplug_and_back():
    esi = esi_devices()
    with link("g1") as lab, segment_service(lab.slave_if) as st:
        transport = st.transports[0]
        assert isinstance(transport, EthercatTransport)
        apps = transport.apps
        master = subprocess.Popen(master_command(lab, "segment_master.py",
                                                 ",".join(map(str, MOVING))),
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True)
        try:
            _line(master)
            k43 = st.call(lambda: [[a.device.get_param(m, 43) for m in range(1, 5)]
                                   for a in apps if a.device is not None])
            moved = st.call(lambda: [[a.device.snapshot(m).position for m in range(1, 5)]
                                     for a in apps if a.device is not None])
            transport.unplug(2)
            assert master.stdin is not None
            master.stdin.write("unplugged\n")
            master.stdin.flush()
            _line(master)
            behind = st.call(lambda: [(a.stack.esc.al_status, a.stack.esc.al_code)
                                      for a in apps])
            transport.plug(2)
            out, err = master.communicate("plugged\n", timeout=120)
        finally:
            if master.poll() is None:
                master.kill()
        assert master.returncode == 0, err[-3000:]
        transitions = [list(a.stack.transitions) for a in apps]
    r = json.loads(out.strip().splitlines()[-1])
    # the scan: three slaves, names and identities from their ESI
    assert r["found"] == 3
    assert r["names"] == [esi[c][0] for c in CODES] == r["sdo_1008"]
    assert r["ids"] == [[ident.VENDOR_ID, esi[c][1], esi[c][2]] for c in CODES]
    # one mapping of 24 + 24 bytes a slave, every slave in OP, one LRW for all of them
    assert r["sizes"] == [[24, 24]] * 3 and r["iomap"] == 144
    assert r["op"] == esm.OP and r["slave_states"] == [esm.OP] * 3
    assert r["expected_wkc"] == 3 * 3
    motion = r["motion"]
    assert motion["wkc_ok"] >= 0.99 * motion["cycles"]
    for n, axis in enumerate(MOVING):      # the chosen axis of each bridge moved 1,000 pulses
        assert all(w & 0x6F == 0x27 for w in motion["final_words"][n]), motion["final_words"]
        assert motion["targets"][n][axis] == motion["start"][n][axis] + 1000
        assert abs(motion["final"][n][axis] - motion["targets"][n][axis]) <= 10, motion
        assert abs(moved[n][axis] - motion["start"][n][axis] - 1000) <= 10, moved
        for other in set(range(4)) - {axis}:
            assert motion["final"][n][other] == motion["start"][n][other]
    # the SDO to the second bridge reached its ID2 and no other motor
    assert k43 == [[K43_DEFAULT] * 4, [K43_DEFAULT, K43_WRITTEN, K43_DEFAULT, K43_DEFAULT],
                   [K43_DEFAULT] * 4], k43
    # unplugged: only the first bridge answers, its port 1 lost the link; SOEM's state
    # check finds the second and the third gone
    gone = r["unplugged"]
    assert gone["wkc_last"] == [3] * 50
    assert gone["states"] == [esm.OP, 0, 0] and gone["first_still_op"] == esm.OP
    assert gone["state_check"] == [esm.OP, 0, 0]
    assert gone["dl_status_1"] == PORT1_CLOSED
    # behind the pulled cable the bridges ran on without frames: SM watchdog, 001Bh
    assert behind[1:] == [(esm.SAFEOP | esm.ERROR_FLAG, 0x001B)] * 2, behind
    # plugged back: a new start-up finds three again and takes them to OP
    assert r["again_found"] == 3 and r["again"]["names"] == r["names"]
    assert r["again"]["op"] == esm.OP and r["again"]["slave_states"] == [esm.OP] * 3
    assert r["again"]["motion"]["wkc_ok"] >= 0.99 * r["again"]["motion"]["cycles"]
    assert r["init"] == esm.INIT
    for t in transitions[1:]:
        assert (esm.OP, esm.SAFEOP, 0x001B) in t and t[-1][1] == esm.INIT


def test_kickcat_scans_three_bridges_and_brings_them_to_op():
    esi = esi_devices()
    with link("g2") as lab, segment_service(lab.slave_if) as st:
        transport = st.transports[0]
        assert isinstance(transport, EthercatTransport)
        r = run_master(lab, "kickcat_segment_master.py", "300")
        targets = [int(a.dictionary.get(0x607A, 0)) for a in transport.apps]
        transitions = [list(a.stack.transitions) for a in transport.apps]
    assert r["found"] == 3
    assert r["sdo_1008"] == [esi[c][0] for c in CODES]
    assert r["product"] == [esi[c][1] for c in CODES]
    assert r["sizes"] == [[24, 24]] * 3
    assert all(s.endswith("SAFE_OP") for s in r["safeop"]), r["safeop"]
    assert all(s.endswith("OPERATIONAL") for s in r["op"]), r["op"]
    assert r["errors"] <= 1
    assert targets == r["last_targets"]              # each bridge got its own image
    assert all(s.endswith("INIT") for s in r["init"])
    assert all((esm.SAFEOP, esm.OP, 0) in t for t in transitions)
