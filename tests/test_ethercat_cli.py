"""``coolmuscle ethercat lab up|down``, ``ethercat esi`` and ``sim --ethercat`` end to end.

The sim runs inside the lab's namespace as a user would run it (docs/ethercat.md);
SOEM scans it from the master's end.
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

from coolmuscle.frontends.ethercat.lab import ip
from ethercat_support import needs_net_admin, stop_sim

ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
LAB = ["--namespace", "cmecatclins", "--master-if", "cmecatclim", "--slave-if", "cmecatclis"]


def coolmuscle(*args: str, timeout: float = 30) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "coolmuscle", *args], capture_output=True,
                          text=True, timeout=timeout, env=ENV)


def test_sim_refuses_lo_and_says_why():
    done = coolmuscle("sim", "--ethercat", "lo", "--no-state")
    assert done.returncode != 0 and "loopback" in done.stderr and "Traceback" not in done.stderr


def test_sim_refuses_an_unknown_bridge():
    done = coolmuscle("sim", "--ethercat", "eth0", "--bridge", "EB99", "--no-state")
    assert done.returncode == 2 and "EB99" in done.stderr


def test_esi_command_writes_xml_with_the_three_bridges_8_1_4():
    done = coolmuscle("ethercat", "esi")
    assert done.returncode == 0
    root = ET.fromstring(done.stdout.split("\n", 1)[1])
    assert [d.findtext("Type") for d in root.iter("Device")] == ["EB01", "EB02", "EB12"]


def _read_until_ready(sim: subprocess.Popen, seconds: float = 60.0) -> str:
    """The sim's stderr up to its ready banner (a loaded machine starts it slowly).

    Read from the descriptor, not the text wrapper: ``communicate()`` reads the
    descriptor later and would not see lines left in the wrapper's buffer."""
    assert sim.stderr is not None
    fd = sim.stderr.fileno()
    seen = b""
    deadline = time.monotonic() + seconds
    while b"ready" not in seen and time.monotonic() < deadline and sim.poll() is None:
        if select.select([fd], [], [], 0.2)[0]:
            seen += os.read(fd, 4096)
    return seen.decode(errors="replace")


def test_esi_of_an_unknown_bridge_and_a_failing_lab_are_one_line_each(
        capsys, monkeypatch) -> None:
    """The lab's and the ESI command's errors: one line, exit 2 for a bad --bridge, 1
    when the lab cannot be made (here: ``ip`` refusing, as without root)."""
    import pytest

    from coolmuscle.frontends.ethercat import lab
    from coolmuscle.tools.cli.app import main

    def refuse(*_args: str) -> None:
        raise lab.LabError("ip netns add cmecatclins: Operation not permitted")
    for args, code in ((["ethercat", "esi", "--bridge", "EB99"], 2),
                       (["ethercat", "lab", "up", *LAB], 1),
                       (["ethercat", "lab", "down", *LAB], 1)):
        monkeypatch.setattr(lab, "up", refuse)
        monkeypatch.setattr(lab, "down", refuse)
        with pytest.raises(SystemExit) as stopped:
            main(args)
        err = capsys.readouterr().err
        assert stopped.value.code == code, err
        assert len(err.splitlines()) == 1 and err.startswith("coolmuscle: "), err
        assert ("EB99" if code == 2 else "not permitted") in err


@needs_net_admin
def test_lab_up_sim_in_the_namespace_soem_scans_lab_down():
    up = coolmuscle("ethercat", "lab", "up", *LAB)
    # a failed up made nothing to remove here ("File exists": another run's lab, which a
    # down in the finally below removed under that run once)
    assert up.returncode == 0, up.stderr
    sim = None
    banner = ""
    try:
        assert "cmecatclim" in up.stdout and "ip netns exec cmecatclins" in up.stdout
        again = coolmuscle("ethercat", "lab", "up", *LAB)          # a second up: one line
        assert again.returncode == 1 and again.stderr == (
            "coolmuscle: the EtherCAT lab is up already: veth cmecatclim <-> cmecatclis (in "
            "network namespace cmecatclins); 'sudo coolmuscle ethercat lab down' removes "
            "it\n")
        sim = subprocess.Popen(["ip", "netns", "exec", "cmecatclins", sys.executable, "-m",
                                "coolmuscle", "sim", "--ethercat", "cmecatclis", "--bridge",
                                "EB12", "--no-state"], env=ENV, stderr=subprocess.PIPE,
                               text=True)
        banner = _read_until_ready(sim)
        scan = subprocess.run([sys.executable, "-c", (
            "import pysoem,sys; m=pysoem.Master(); m.open('cmecatclim'); n=m.config_init();"
            "print(n, m.slaves[0].name, hex(m.slaves[0].id)); m.close()")],
            capture_output=True, text=True, timeout=30)
        assert scan.stdout.split()[0] == "1", scan.stderr
        assert "EB12" in scan.stdout and "0xeb0012" in scan.stdout
    finally:
        err = ""
        if sim is not None:
            err = stop_sim(sim, 10)
            err = banner + err
        down = coolmuscle("ethercat", "lab", "down", *LAB)   # before any assertion here
    assert "Traceback" not in err
    assert "virtual CM1/CM1/CM2/CM2 ID1-ID4 ready" in err, err
    assert "ethercat: cmecatclis (EB12" in err
    assert down.returncode == 0 and "cmecatclins" in down.stdout
    assert "cmecatclins" not in ip("netns", "list").stdout
    again = coolmuscle("ethercat", "lab", "down", *LAB)
    assert "nothing to remove" in again.stdout
