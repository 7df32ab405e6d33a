"""``coolmuscle sim --ethercat IFACE --bridges ...`` and the machine file's ``[ethercat]``.

The segment as a user starts it (docs/ethercat.md "Several bridges on one segment"):
the options, the machine-file section and its ``[[axis]] bridge = n`` tables, the state
folder of each further bridge, and SOEM scanning what the command serves.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from coolmuscle.chain import Chain
from coolmuscle.chain.machine import MachineFileError, parse_machine
from coolmuscle.sim.kernel import Kernel
from ethercat_support import link, needs_net_admin, stop_sim

ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}

SEGMENT_TOML = """
name = "a 12-axis gantry"
[ethercat]
bridges = ["EB01", "EB02", "EB02"]

[[axis]]
motor = 2
params = { K43 = 110 }

[[axis]]
bridge = 3
motor = 2
params = { K43 = 120 }
"""


def coolmuscle(*args: str, timeout: float = 30) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "coolmuscle", *args], capture_output=True,
                          text=True, timeout=timeout, env=ENV)


@pytest.mark.parametrize(("args", "said"), [
    (["--bridge", "EB02", "--bridges", "EB02,EB12"], "exclude each other"),
    (["--bridges", "EB02,EB99"], "EB99"),
    (["--bridges", "EB02,,EB12"], "comma-separated"),
    (["--bridges", ",".join(["EB02"] * 65)], "65 bridges; a segment has at most 64"),
])
def test_bad_bridges_are_one_line_and_exit_2(args: list[str], said: str) -> None:
    done = coolmuscle("sim", "--ethercat", "eth0", *args, "--no-state")
    assert done.returncode == 2 and said in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_bridges_need_ethercat() -> None:
    done = coolmuscle("sim", "--bridges", "EB02,EB12", "--no-state")
    assert done.returncode == 2 and "--ethercat" in done.stderr


def test_the_machine_file_names_the_bridges_and_each_axis_its_bridge() -> None:
    machine = parse_machine(SEGMENT_TOML, "gantry.toml")
    assert machine.bridges == ("EB01", "EB02", "EB02")
    assert [(a.bridge, a.motor) for a in machine.axes] == [(1, 2), (3, 2)]
    third = machine.for_bridge(3)
    assert [(a.bridge, a.motor, a.params) for a in third.axes] == [(1, 2, {43: 120})]
    assert machine.for_bridge(2).axes == [] and "bridge 3" in third.source
    # a chain takes bridge 1's tables only
    chain = Chain(Kernel(), 4, firmware="cm1", machine=machine)
    assert [chain.get_param(m, 43) for m in range(1, 5)] == [100, 110, 100, 100]


@pytest.mark.parametrize(("text", "said"), [
    ('[ethercat]\nbridges = ["EB02"]\n[[axis]]\nbridge = 2\n', "names 1 bridge"),
    ('[ethercat]\nbridge = ["EB02"]\n', "unknown key 'bridge'"),
    ('[ethercat]\nbridges = "EB02"\n', "list"),
    ('[[axis]]\nbridge = 2\n', "names 0 bridge"),
    ('[[axis]]\nmotor = 1\n[[axis]]\nmotor = 1\nbridge = 1\n', "same motor"),
])
def test_a_wrong_ethercat_section_names_the_key(text: str, said: str) -> None:
    with pytest.raises(MachineFileError, match=said):
        parse_machine(text, "m.toml")


@needs_net_admin
def test_sim_serves_the_bridges_of_a_machine_file_and_soem_finds_them(tmp_path: Path) -> None:
    machine = tmp_path / "gantry.toml"
    machine.write_text(SEGMENT_TOML)
    state = tmp_path / "state"
    with link("gc") as lab:
        sim = subprocess.Popen([sys.executable, "-m", "coolmuscle", "sim", "--ethercat",
                                lab.slave_if, "--machine", str(machine), "--state", str(state)],
                               env=ENV, stderr=subprocess.PIPE, text=True)
        banner = ""
        try:
            assert sim.stderr is not None
            banner = sim.stderr.readline() + sim.stderr.readline()
            script = textwrap.dedent("""
                import json, struct, sys, pysoem
                m = pysoem.Master(); m.open(sys.argv[1])
                n = m.config_init()
                k43 = [[struct.unpack("<I", s.sdo_read(0x60F6 + 0x800 * a, 23))[0]
                        for a in range(4)] for s in m.slaves]
                print(json.dumps({"found": n, "names": [s.name for s in m.slaves],
                                  "k43": k43}))
                m.close()
            """)
            scan = subprocess.run(["ip", "netns", "exec", lab.namespace, sys.executable, "-c",
                                   script, lab.master_if], capture_output=True, text=True,
                                  timeout=60)
        finally:
            err = stop_sim(sim)
    assert "virtual 3 bridges EB01/EB02/EB02, each ID1-ID4 ready" in banner, banner + err
    assert "EB01, EB02, EB02: 3 EtherCAT slaves in a line" in banner
    assert "Traceback" not in err
    r = json.loads(scan.stdout.strip().splitlines()[-1]) if scan.stdout.strip() else scan.stderr
    assert r["found"] == 3, r
    assert [name.split()[0] for name in r["names"]] == ["EB01", "EB02", "EB02"]
    assert r["k43"] == [[100, 110, 100, 100], [100] * 4, [100, 120, 100, 100]]
    for position in (2, 3):              # each further bridge's chain keeps its own state
        assert (state / f"bridge-{position}" / "coolmuscle.sqlite3").exists()
    assert (state / "coolmuscle.sqlite3").exists()
