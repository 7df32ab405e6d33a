"""The EtherCAT lab without root: ``coolmuscle ethercat lab run -- COMMAND``.

A user made for the test (no privileges, a copy of the sources it owns) runs the
pysoem session of tests/test_ethercat_soem.py to OP through ``lab run``: a user and
network namespace of its own, the veth pair inside, ``sim --ethercat`` on one end (its
one note: no SCHED_FIFO there), SOEM on the other; the exit status is the master's and
nothing of it is left once it ends.  ``lab up`` without root says what to use instead.
As root ``lab run`` makes only the network namespace.  Where a kernel refuses user
namespaces, the message names the setting to change (read from /proc/sys).
"""

from __future__ import annotations

import errno
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from coolmuscle.frontends.ethercat import lab
from unprivileged_support import Unprivileged, unprivileged_user, veth_lock

MASTERS = Path(__file__).parent / "ethercat_masters"
ROOT = Path(__file__).resolve().parents[1]

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("rootless")]


@pytest.fixture(scope="module")
def user() -> Iterator[Unprivileged]:
    if lab.userns_problem() is not None:
        pytest.skip(f"no user namespace for an unprivileged user: {lab.userns_problem()}")
    with unprivileged_user() as made:
        made.copy(MASTERS / "soem_master.py")
        yield made


def _result(done: subprocess.CompletedProcess[str]) -> dict[str, object]:
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    result: dict[str, object] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def test_an_unprivileged_user_runs_the_pysoem_session_to_op(user: Unprivileged) -> None:
    with veth_lock():
        done = user.coolmuscle("ethercat", "lab", "run", "--", user.python,
                               "soem_master.py", "cmlab-master", "full", "2000")
    r = _result(done)
    assert r["found"] == 1 and r["name"] == "EB02 CM2 EtherCAT Cool MUSCLE Bridge"
    assert r["sdo_1008"] == "EB02 CM2 EtherCAT Cool MUSCLE Bridge"
    assert (r["out_len"], r["in_len"]) == (24, 24)
    assert r["safeop"] == 4 and r["op"] == 8 and r["init"] == 1
    assert isinstance(r["wkc_ok"], int) and r["wkc_ok"] >= 0.99 * 2000, r["missed"]
    err = done.stderr
    assert "EtherCAT lab in a user and network namespace of its own" in err, err
    assert "ethercat: cmlab-slave (EB02, EtherCAT slave" in err
    assert err.count("runs at normal priority (SCHED_FIFO needs") == 1, err
    assert user.processes() == []


def test_the_exit_status_is_the_commands_and_the_link_is_its_alone(
        user: Unprivileged) -> None:
    with veth_lock():
        done = user.coolmuscle("ethercat", "lab", "run", "--no-sim", "--", "sh", "-c",
                               'ip -o link show "$COOLMUSCLE_LAB_MASTER_IF" && '
                               'ip -o link show "$COOLMUSCLE_LAB_SLAVE_IF" && exit 7')
    assert done.returncode == 7, done.stderr
    assert "cmlab-master@cmlab-slave" in done.stdout and "alias coolmuscle-lab" in done.stdout
    assert subprocess.run(["ip", "link", "show", "cmlab-master"],
                          capture_output=True).returncode != 0      # never in ours
    assert user.processes() == []


def test_lab_up_without_root_says_to_use_lab_run(user: Unprivileged) -> None:
    done = user.coolmuscle("ethercat", "lab", "up")
    assert (done.returncode, done.stdout) == (1, ""), done.stderr
    assert done.stderr == ("coolmuscle: ethercat lab up needs root (a network namespace for "
                           "the slave's end); without root run the master in a lab of its "
                           "own: coolmuscle ethercat lab run -- COMMAND (docs/ethercat.md)\n")


def test_as_root_lab_run_makes_only_the_network_namespace(tmp_path: Path) -> None:
    if not lab.privileged():
        pytest.skip("root's path of lab run")
    env = {"PYTHONPATH": str(ROOT / "src"), "PATH": "/usr/bin:/bin:/usr/sbin:/sbin",
           "COLUMNS": "200"}
    with veth_lock():
        done = subprocess.run([sys.executable, "-m", "coolmuscle", "ethercat", "lab", "run",
                               "--", sys.executable, str(MASTERS / "soem_master.py"),
                               "cmlab-master", "invalid"], capture_output=True, text=True,
                              timeout=300, env=env, cwd=tmp_path)
    r = _result(done)
    assert r["init"] == 1 and r["al_status_code"] == 0x0011
    assert "EtherCAT lab in a network namespace of its own" in done.stderr


def test_a_missing_command_is_one_line() -> None:
    done = subprocess.run([sys.executable, "-m", "coolmuscle", "ethercat", "lab", "run", "--",
                           "no-such-master-program"], capture_output=True, text=True,
                          timeout=120, env={"PYTHONPATH": str(ROOT / "src"),
                                            "PATH": "/usr/bin:/bin", "COLUMNS": "200"})
    assert (done.returncode, done.stderr) == (
        1, "coolmuscle: no command 'no-such-master-program' to run in the lab\n")


@pytest.mark.parametrize("settings, words", [
    ({"user.max_user_namespaces": 0}, "user.max_user_namespaces=0"),
    ({"kernel.unprivileged_userns_clone": 0}, "kernel.unprivileged_userns_clone=1"),
    ({"kernel.apparmor_restrict_unprivileged_userns": 1},
     "kernel.apparmor_restrict_unprivileged_userns=0"),
])
def test_what_a_kernel_refusing_user_namespaces_needs_is_named(
        monkeypatch: pytest.MonkeyPatch, settings: dict[str, int], words: str) -> None:
    monkeypatch.setattr(lab, "_sysctl", lambda name: settings.get(name))
    problem = lab.userns_problem()
    assert problem is not None and words in problem and "sysctl -w" in problem
    refused = lab._refused(OSError(errno.EPERM, "Operation not permitted"), user=True)
    assert refused == ("cannot make a user and network namespace: Operation not permitted: "
                       + problem)


def test_a_kernel_that_allows_them_has_no_problem(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(lab, "_sysctl", lambda name: {"user.max_user_namespaces": 63000}
                        .get(name))
    assert lab.userns_problem() is None
