"""The ``ethercat`` wire faults under a real master: pysoem (SOEM) on a veth pair.

Two bridges (EB02, EB12) run in this process behind one veth end; the master runs in
its own namespace on the other (tests/ethercat_masters/wire_faults_master.py).  The test
installs each fault through the device API (the model's thread) and tells the master
to go on; what SOEM reports is the oracle: ``receive_processdata``'s working counter
below ``expected_wkc`` (ETG.1000.4 table 12), no frame (-1), an SDO that still
completes after its answer was lost (SOEM's mailbox repeat request), the AL status
code 001Bh after a link down (manual 5.2.2) and OP again after the acknowledge.
The same faults sans IO: tests/test_ethercat_wire_faults.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.ethercat.engine import esm
from coolmuscle.frontends.ethercat.transport import EthercatTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.sim.kernel import Kernel
from ethercat_support import link, master_command, needs_net_admin, stop_sim

pytestmark = [needs_net_admin, pytest.mark.realtime]

CODES = ("EB02", "EB12")
#: LRW of two bridges, each reading and writing: 3 a bridge.
EXPECTED_WKC = 6


def bridge_chain(kernel: Kernel, _position: int, firmware: str) -> Chain:
    return Chain(kernel, 4, firmware=firmware)


def _ready(proc: subprocess.Popen[str]) -> None:
    assert proc.stdout is not None
    line = proc.stdout.readline().strip()
    if line != "READY":
        proc.kill()
        raise AssertionError(f"the master said {line!r}: {proc.communicate()[1][-3000:]}")


def _go(proc: subprocess.Popen[str], phase: str) -> None:
    assert proc.stdin is not None
    proc.stdin.write(phase + "\n")
    proc.stdin.flush()


def test_pysoem_sees_working_counter_errors_lost_frames_a_repeated_mailbox_and_001b():
    records: list[str] = []
    with link("wf") as lab, ServiceThread(
            lambda: Chain(None, 4, firmware="cm2"),
            lambda: [EthercatTransport(lab.slave_if, bridges=CODES,
                                       chains=bridge_chain)]) as st:
        transport = st.transports[0]
        assert isinstance(transport, EthercatTransport) and transport.segment is not None
        device = transport.segment.device
        assert device is not None
        st.call(lambda: device.subscribe(
            lambda e: records.append(e.text) if e.kind == "wire" else None))

        def inject(kind: str, **schedule: Any) -> None:
            st.call(lambda: device.inject_wire_fault("ethercat", kind, **schedule))

        master = subprocess.Popen(master_command(lab, "wire_faults_master.py"),
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True)
        try:
            _ready(master)
            inject("wkc", every=5, count=20)
            _go(master, "wkc")
            _ready(master)
            inject("lost_frame", every=4, count=10)
            _go(master, "lost")
            _ready(master)
            inject("mailbox_lost", count=1)
            _go(master, "mailbox")
            _ready(master)
            inject("link_down", bridge=2, until=0.5)
            _go(master, "link")
            _ready(master)
            out, err = master.communicate("done\n", timeout=120)
        finally:
            if master.poll() is None:
                master.kill()
        assert master.returncode == 0, err[-3000:]
        faults = transport.segment.faults
        assert faults is not None
        states = [(a.stack.esc.al_status, a.stack.esc.al_code) for a in transport.apps]
    r = json.loads(out.strip().splitlines()[-1])
    assert r["found"] == 2 and r["op"] == esm.OP and r["expected_wkc"] == EXPECTED_WKC
    assert set(r["clean"]) == {EXPECTED_WKC}                  # fault free: every cycle
    # a working counter off by one: receive_processdata returns expected - 1, 20 times
    assert r["wkc"].count(EXPECTED_WKC - 1) == 20
    assert set(r["wkc"]) == {EXPECTED_WKC, EXPECTED_WKC - 1}
    # lost frames: no frame came back (SOEM's EC_NOFRAME), 10 times
    assert r["lost"].count(-1) == 10 and set(r["lost"]) == {EXPECTED_WKC, -1}
    # the mailbox answer lost once: SOEM reads it again (repeat request), the SDO completes
    assert r["mailbox"].get("name") == r["names"][0] and r["names"][0].startswith("EB02"), \
        r["mailbox"]
    assert set(r["mailbox"]["wkcs"]) == {EXPECTED_WKC}
    assert sum("mailbox answer (SM1 emptied) never reaches the master" in t
               for t in records) == 1, records
    # the link into the second bridge down for 0.5 s: the first alone answers (3), the
    # second's SM watchdog runs out: SAFE-OP + ERROR, 001Bh, as SOEM reads it
    link_phase = r["link"]
    assert set(link_phase["wkcs"]) == {EXPECTED_WKC, 3} and link_phase["wkcs"][-1] == 6
    assert link_phase["wkcs"].count(3) > 50                 # 0.5 s of 1 ms cycles
    assert link_phase["after"][0] == [esm.OP, 0]
    assert link_phase["after"][1] == [esm.SAFEOP | esm.ERROR_FLAG, esm.SM_WATCHDOG]
    # acknowledged and taken to OP again: every cycle complete
    assert link_phase["recovered"] == [[esm.OP, 0], [esm.OP, 0]]
    assert set(link_phase["wkcs_again"]) == {EXPECTED_WKC}
    assert r["init"] == esm.INIT and states[1][0] == esm.INIT
    assert sum(t.endswith("is pulled") for t in records) == 1
    assert sum(t.endswith("is back") for t in records) == 1
    assert faults.lost == 11 and faults.changed == 20


MACHINE = """
[ethercat]
bridges = ["EB02", "EB02"]

[[wire.fault]]
door = "ethercat"
kind = "wkc"
every = 2

[[wire.fault]]
door = "ethercat"
kind = "lost_frame"
way = "back"
every = 7
at = 3600
"""

SCAN = textwrap.dedent("""
    import json, sys, time, pysoem
    m = pysoem.Master(); m.open(sys.argv[1])
    n = m.config_init()
    m.config_map()
    wkcs = []
    for _ in range(40):
        m.send_processdata(); wkcs.append(m.receive_processdata(10_000)); time.sleep(0.001)
    print(json.dumps({"found": n, "expected": m.expected_wkc, "wkcs": wkcs}))
    m.close()
""")


def test_sim_takes_the_ethercat_faults_of_a_machine_file(tmp_path: Path) -> None:
    """``coolmuscle sim --ethercat IFACE --machine FILE``: the file's ``[[wire.fault]]``
    reach the segment (one LRW in two one short; a fault not yet live does nothing)."""
    machine = tmp_path / "flaky.toml"
    machine.write_text(MACHINE)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    with link("wm") as lab:
        sim = subprocess.Popen([sys.executable, "-m", "coolmuscle", "sim", "--ethercat",
                                lab.slave_if, "--machine", str(machine)],
                               env=env, stderr=subprocess.PIPE, text=True)
        try:
            assert sim.stderr is not None
            banner = sim.stderr.readline() + sim.stderr.readline()
            scan = subprocess.run(["ip", "netns", "exec", lab.namespace, sys.executable, "-c",
                                   SCAN, lab.master_if], capture_output=True, text=True,
                                  timeout=60)
        finally:
            err = stop_sim(sim)
    assert "2 EtherCAT slaves in a line" in banner, banner + err
    assert "Traceback" not in err
    r = json.loads(scan.stdout.strip().splitlines()[-1]) if scan.stdout.strip() else scan.stderr
    assert r["found"] == 2 and r["expected"] == EXPECTED_WKC, r
    # the fault counts LRW frames from the first: every second one comes back one short
    assert r["wkcs"] == [EXPECTED_WKC, EXPECTED_WKC - 1] * 20, r
