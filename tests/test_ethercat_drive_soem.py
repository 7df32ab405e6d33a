"""SOEM (pysoem) drives the bridge's CiA402 axes over a veth pair: a real master's view.

ethercat-bridge-users-guide.txt 6.1 (06h/07h/0Fh to Operation enabled, fault and
fault reset), 6.3 (csp ramp on four axes), Appendix 4 (homing on a stopper),
Appendix 1.1 (CMD mode F307h), 7.1 (CPIO outputs, seen by ``?50`` on the motor's own
line); the README's pysoem example; KickCAT, a second master, reading the drive's
objects and moving all axes.  The veth pairs and namespaces (prefix ``cmec2``) are made
and always deleted by each test; the master runs in the namespace, the slave in this
process in real time.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.ethercat.lab import veth_pair
from coolmuscle.frontends.ethercat.transport import EthercatTransport
from coolmuscle.frontends.transports.service import ServiceThread
from ethercat_drive_support import Bench
from ethercat_support import master_command, needs_net_admin, run_master

pytestmark = [needs_net_admin, pytest.mark.realtime]

DATA = Path(__file__).parent / "data"
STOPPERS = DATA / "ethercat_stoppers.toml"
FAULT = DATA / "ethercat_fault_id2.toml"
IN_POSITION_WINDOW = 10        # pulses: what the motor's own in-position settles within


def servo_lag() -> int:
    """The servo model's own lag on the same ramp (2 pulses a ms), in virtual time."""
    b = Bench("EB02")
    b.enable((1,))
    lag = 0
    for i in range(1, 2001):
        b.pdo(1, 0x0F, 2 * i)
        b.cycles(1)
        lag = max(lag, 2 * i - b.position(1))
    return lag


def run_drive_master(lab, st) -> dict:
    """The master in the namespace; injects the alarm when it asks (machine file)."""
    cmd = master_command(lab, "drive_master.py")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        lines = []
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("STEP fault"):
                st.call(lambda: st.chain.load_machine(FAULT))
        proc.wait(timeout=100)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if proc.returncode != 0:
        raise AssertionError(f"drive_master failed:\n{proc.stderr.read()[-3000:]}")
    return json.loads(lines[-1])


def test_soem_drives_cia402_csp_homing_cmd_cpio_and_fault_reset_6_1_6_3_6_4_7_1():
    lag0 = servo_lag()
    with veth_pair("cmec2a", inside="master") as lab:
        with ServiceThread(lambda: Chain(None, 4, firmware="cm2", machine=STOPPERS),
                           lambda: [EthercatTransport(lab.slave_if, "EB02")]) as st:
            r = run_drive_master(lab, st)
            transport = st.transports[0]
            # the bridge's cycles are kernel events 1 ms apart (virtual time); a cycle
            # the paced kernel reached late held the motor's command that much longer
            late_ms = math.ceil(transport.max_late_s * 1000)
            print(r, "bridge cycles", transport.cycles, "late", transport.late_cycles,
                  "latest ms", late_ms)
            out4 = st.call(lambda: st.chain.execute("?50.4", origin="host"))
            origin1 = st.call(lambda: st.chain.snapshot(1).extra["origin_done"])
            k42_3 = st.call(lambda: st.chain.get_param(3, 42))
    assert r["op"] == 8
    assert r["sw_start"] == [0x0240] * 4                          # switch on disabled
    assert r["sw_06"] == [0x0221] * 4 and r["sw_07"] == [0x0223] * 4
    assert r["sw_0f"] == [0x1227] * 4                             # operation enabled, csp
    assert (r["al_after_ramp"], r["al_code"]) == (8, 0), "the slave left OP during the ramp"
    for a in range(4):                                            # 6.3: on target, in step
        assert abs(r["ramp_end"][a] - (r["ramp_start"][a] + 4000)) <= IN_POSITION_WINDOW
        # the servo's own lag, plus 2 pulses for each ms a bridge cycle came late (the
        # motor follows the stream the bridge could give it), and one cycle more
        assert r["max_lag3"][a] <= lag0 + 2 * (2 + late_ms), (r["max_lag3"], lag0, late_ms)
    assert r["hm_switch"] >= 0 and r["hm_running"] >= 0           # Appendix 4: in progress
    assert r["hm_cycles"] >= 0 and r["hm_sw"] & 0x3400 == 0x1400  # bits 10 and 12
    assert abs(r["hm_pos"]) <= 2 and origin1 == 1
    assert r["k42_3"] == 100 == k42_3                             # 60F6h reached ID3
    assert r["cmd_switch"] >= 0 and r["cmd_ack"] == 0xF3          # Appendix 1.1 / 7.1.3
    assert r["cmd_done"] == 0xF8
    assert r["cpio_switch"] >= 0 and r["cpio_sw"] >> 12 == 0xC    # 7.1.3 CPIO statusword
    assert out4 == ["OUT.4=03"]                                   # ?50 on the motor's line
    assert r["f530_tx"] > 1000                                    # 7.4 CM port counters
    assert r["csp_again"] >= 0 and r["cml_switch"] >= 0           # Appendix 3.3, 3.2
    assert r["q99"] == ["Ux.1=8\r\n"]                            # Appendix 2.3
    assert len(r["q90"]) == 18 and r["q90"][0].startswith("K20.1=")   # Appendix 2.5
    assert r["too_long"] == 0x06070012                            # 7.2.2: over 64 bytes
    assert r["fault_cycles"] >= 0 and r["fault_sw"] & 0x4F == 0x08 and r["fault_sw"] & 0x4000
    assert r["reset_sw"] & 0x4F == 0x40                           # 15: switch on disabled
    assert r["reenabled_sw"] == 0x1227                            # state B cleared the alarm
    assert r["init"] == 1


def test_readme_pysoem_example_moves_a_virtual_motor():
    example = Path(__file__).parents[1] / "examples" / "ethercat_pysoem_move.py"
    with veth_pair("cmec2b", inside="master") as lab:
        with ServiceThread(lambda: Chain(None, 4, firmware="cm2"),
                           lambda: [EthercatTransport(lab.slave_if, "EB02")]) as st:
            done = subprocess.run(["ip", "netns", "exec", lab.namespace, sys.executable,
                                   str(example), lab.master_if],
                                  capture_output=True, text=True, timeout=60)
            position = st.call(lambda: st.chain.snapshot(1).position)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "controlword 0x000f: statusword 0x1227" in done.stdout
    assert done.stdout.strip().splitlines()[-1].startswith("target 4000, 6064h 4000")
    assert position == 4000


def test_kickcat_reads_the_drive_objects_and_moves_all_axes_6_1_6_3_7_3():
    """A second, independent master: KickCAT (its binding reads SDOs, writes PDOs)."""
    with veth_pair("cmec2k", inside="master") as lab:
        with ServiceThread(lambda: Chain(None, 4, firmware="cm2"),
                           lambda: [EthercatTransport(lab.slave_if, "EB02")]):
            r = run_master(lab, "kickcat_drive_master.py", timeout=90)
    assert r["6502"] == 0xA0 and r["6061"] == [8] * 4             # 6.2.1, 6.2.2 note 1
    assert r["60e3"] == [1, 2, 3, 4]                              # 6.4.1
    assert r["f511"] == [2, 6, 1]                                 # 7.3: CM2, 176,800, 1 ms
    assert r["f591"] == "Null\r\n"                                # 7.2.2: nothing yet
    assert "OPERATIONAL" in r["op"].upper()
    assert all(w & 0x6F == 0x21 for w in r["sw_06"]), r
    assert all(w & 0x6F == 0x23 for w in r["sw_07"]), r
    assert all(w & 0x6F == 0x27 and w & 0x1000 for w in r["sw_0f"]), r
    assert all(abs(e - (s + 1000)) <= IN_POSITION_WINDOW for s, e in zip(r["start"], r["end"]))
    assert r["f530_tx"] > 500
