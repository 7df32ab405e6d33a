"""The pytest plug-in (coolmuscle.testing) as a user runs it: examples/user-project's own
pytest in a subprocess, the plug-in named with ``-p`` (an installed package has its
``pytest11`` entry point; pyproject.toml).

* the sample's tests pass; on the broken bank variant exactly the placement test fails,
  naming the CML line that was running and showing the trace around it;
* ``--cm-coverage-xml`` writes Cobertura XML that coverage-04.dtd allows, with every
  line of the sample's banks run; the terminal shows the table;
* nothing the fixtures started is left once pytest has ended (processes, ports,
  namespaces: the ledger it wrote, checked again from outside, and no process that
  carries the run's token);
* loading the plug-in imports nothing of coolmuscle beyond the package itself, so
  ``pytest --co`` stays fast; an unobserved chain's banks carry no observer.
"""

from __future__ import annotations

import os
import subprocess
import sys
import uuid
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from coolmuscle.client.program import load_program
from coolmuscle.testing.coverage import BankCoverage, line_ranges
from coolmuscle.testing.lab import unavailable
from coolmuscle.testing.ledger import Ledger, leftovers, read_ledger
from fixtures import ROOT, SRC
from schema_support import DtdError, validate_cobertura

SAMPLE = ROOT / "examples" / "user-project"
PICK = SAMPLE / "banks" / "pick.cml"


def run_sample(tmp_path: Path, *args: str, **env: str) -> tuple[subprocess.CompletedProcess[str],
                                                               str]:
    """The sample project's pytest (its own rootdir and settings); the run's token."""
    token = uuid.uuid4().hex[:12]
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), str(SAMPLE)]),
                   "COOLMUSCLE_TESTING_RUN": token, **env}
    environment.pop("PYTEST_ADDOPTS", None)
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "coolmuscle.testing.plugin", "-p",
         "no:cacheprovider", "-q", "-n", "0", "--basetemp", str(tmp_path / "base"), *args],
        cwd=SAMPLE, env=environment, capture_output=True, text=True, timeout=600)
    return done, token


@pytest.mark.slow
def test_the_sample_project_passes_with_coverage_and_leaves_nothing(tmp_path: Path) -> None:
    xml, ledger = tmp_path / "coverage.xml", tmp_path / "ledger.jsonl"
    done, token = run_sample(tmp_path, "--cm-coverage-xml", str(xml), "--cm-ledger",
                             str(ledger))
    assert done.returncode == 0, done.stdout + done.stderr
    lab = unavailable() is None                  # the lab test runs as root, else skips
    assert ("8 passed" if lab else "7 passed, 1 skipped") in done.stdout, done.stdout
    assert "coolmuscle bank coverage" in done.stdout
    assert any(line.split()[:5] == ["banks/pick.cml", "2", "9", "9", "100%"]
               for line in done.stdout.splitlines()), done.stdout
    root = validate_cobertura(xml)
    [pick] = [c for c in root.iter("class") if c.get("filename") == "banks/pick.cml"]
    hits = {int(line.get("number", 0)): int(line.get("hits", 0))
            for line in pick.find("lines").iter("line")}      # type: ignore[union-attr]
    bank_lines = sorted({line.number for bank in load_program(PICK).banks
                         for line in bank.body})
    assert sorted(hits) == bank_lines and all(hits.values())
    assert {m.get("name") for m in pick.iter("method")} == {"B1.1", "L1.1"}
    entries = read_ledger(ledger)
    noted = {"process", "port"} | ({"namespace"} if lab else set())
    assert {e["kind"] for e in entries} >= noted            # what the fixtures started
    assert leftovers(entries, token) == []


@pytest.mark.slow
def test_a_broken_bank_fails_the_right_test_naming_its_line(tmp_path: Path) -> None:
    done, _token = run_sample(tmp_path, "tests/test_banks.py",
                              CONVEYOR_BANKS="banks/pick_broken.cml")
    out = done.stdout
    assert done.returncode == 1, out + done.stderr
    assert "1 failed, 4 passed" in out
    assert ("FAILED tests/test_banks.py::test_the_part_is_picked_at_2000_and_placed_at_6000"
            in out)
    broken = (SAMPLE / "banks" / "pick_broken.cml").read_text().splitlines()
    assert broken[19] == "T2.1" and PICK.read_text().splitlines()[19] == "T1.1"
    assert "position at 1.6 s is 2000 pulses, expected 6000 ± 2" in out
    assert "bank line running then: banks/pick_broken.cml:20 T2.1" in out
    piece = [line for line in out.splitlines() if "banks/pick_broken.cml:20 T2.1" in line
             and "2000" in line]
    assert len(piece) >= 8                                   # the trace rows around it
    assert any(line.lstrip("E ").startswith("->  1.600") for line in out.splitlines())


def test_the_lab_is_skipped_with_its_reason_where_it_cannot_be_made(
        tmp_path: Path) -> None:
    """Where no lab can be made the sample's lab test is skipped with the reason.  On a
    machine that makes labs, the sample runs with a PATH that has no ``ip`` (the python
    it runs is named in full), which is one of the reasons a lab cannot be made."""
    reason = unavailable()
    env: dict[str, str] = {}
    if reason is None:
        env["PATH"] = str(tmp_path / "no-ip")
        (tmp_path / "no-ip").mkdir()
        reason = "the EtherCAT lab needs the 'ip' command (iproute2)"
    done, _ = run_sample(tmp_path, "tests/test_lab.py", "-rs", **env)
    assert done.returncode == 0 and reason in done.stdout, done.stdout + done.stderr
    assert "1 skipped" in done.stdout, done.stdout


@pytest.mark.slow
def test_without_root_the_lab_test_runs_in_a_lab_of_its_own() -> None:
    """As a user made for the test: the sample's lab test is skipped with the command to
    use, and passes under it (pytest in a user and network namespace of its own, where
    ``cm_lab`` makes its pair and serves the bridge; the ledger finds nothing left)."""
    from coolmuscle.frontends.ethercat.lab import userns_problem
    from coolmuscle.testing.lab import RUN_INSIDE
    from unprivileged_support import unprivileged_user, veth_lock
    if userns_problem() is not None:
        pytest.skip(f"no user namespace for an unprivileged user: {userns_problem()}")
    with unprivileged_user() as user:
        sample = user.copy(SAMPLE, "user-project")
        user.path.insert(1, str(sample))
        pytest_args = [user.python, "-m", "pytest", "-p", "coolmuscle.testing.plugin", "-p",
                       "no:cacheprovider", "-q", "-n", "0", "-rs", "--basetemp",
                       str(user.home / "base"), "--cm-ledger", str(user.home / "ledger.jsonl"),
                       "tests/test_lab.py"]
        alone = user.run(pytest_args, cwd=sample)
        assert alone.returncode == 0, alone.stdout + alone.stderr
        assert "1 skipped" in alone.stdout and RUN_INSIDE in alone.stdout, alone.stdout
        with veth_lock():
            inside = user.run([user.python, "-m", "coolmuscle", "ethercat", "lab", "run",
                               "--no-sim", "--", *pytest_args], cwd=sample)
        assert inside.returncode == 0, inside.stdout[-3000:] + inside.stderr[-3000:]
        assert "1 passed" in inside.stdout, inside.stdout
        noted = read_ledger(user.home / "ledger.jsonl")
        assert {e["kind"] for e in noted} == {"process", "namespace"}, noted
        assert user.processes() == []


def test_loading_the_plugin_imports_nothing_else() -> None:
    code = ("import sys, pytest, coolmuscle; before = set(sys.modules); "
            "import coolmuscle.testing.plugin; print(sorted(set(sys.modules) - before))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(SRC)}, timeout=120)
    assert done.stdout.strip() == "['coolmuscle.testing', 'coolmuscle.testing.plugin']", \
        done.stdout + done.stderr


def test_collecting_the_sample_loads_no_model() -> None:
    """``pytest --co`` of a project with the plug-in: no part of the model is imported."""
    code = ("import sys, pytest; code = pytest.main(['-p', 'coolmuscle.testing.plugin', "
            "'-p', 'no:cacheprovider', '--co', '-q', '-n', '0', 'tests/test_banks.py']); "
            "print(sorted(m for m in sys.modules if m.startswith('coolmuscle.'))); "
            "sys.exit(code)")
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), str(SAMPLE)])}
    done = subprocess.run([sys.executable, "-c", code], cwd=SAMPLE, env=environment,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "5 tests collected" in done.stdout
    loaded = done.stdout.strip().splitlines()[-1]
    assert "'coolmuscle.testing.plugin'" in loaded
    for part in ("coolmuscle.chain", "coolmuscle.motor", "coolmuscle.testing.rig",
                 "coolmuscle.tools"):
        assert f"'{part}" not in loaded, loaded


def test_an_unobserved_chain_has_no_observer_and_one_that_was_has_none_after(
        make_chain: object) -> None:
    from coolmuscle.chain.daisy import Chain
    chain = Chain()
    motor = chain.motors[1]
    assert (motor.program.line_observer, motor.ladder.line_observer,
            motor.logic_motion.line_observer) == (None, None, None)
    seen: list[object] = []
    remove = chain.observe_bank_lines(seen.append)
    for line in ("B1.1", "P1.1=100", "END", "L1.1", "V1.1=1;", "END", "K63.1=1", "[L1.1",
                 "[1.1"):
        chain.execute(line)
    chain.kernel.run(until=10_000_000)
    remove()
    assert motor.program.line_observer is None and motor.ladder.line_observer is None
    assert seen and chain.execute("?L1.1") == ["V1.1=1;"]
    chain.close()


def test_the_leftover_check_bites(tmp_path: Path) -> None:
    """A process group that runs, a port that listens: both reported; then neither."""
    import socket
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"],
                            start_new_session=True)
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    ledger = Ledger("t", tmp_path / "l.jsonl")
    ledger.note("process", pgid=proc.pid)
    ledger.note("port", proto="tcp", port=server.getsockname()[1])
    try:
        assert len(leftovers(read_ledger(tmp_path / "l.jsonl"))) == 2
    finally:
        proc.kill()
        proc.wait()
        server.close()
    assert leftovers(ledger.entries) == []


def test_coverage_merges_workers_and_the_dtd_check_bites(tmp_path: Path) -> None:
    one, two = BankCoverage(), BankCoverage()
    one.add_hits("banks/a.cml", "B1.1", {3: 1, 4: 0})
    two.add_hits("banks/a.cml", "B1.1", {4: 2, 5: 0})
    one.merge(two.data())
    assert one.files["banks/a.cml"].hits == {3: 1, 4: 2, 5: 0}
    assert line_ranges([5, 1, 2, 3, 9]) == "1-3, 5, 9"
    path = one.write_xml(tmp_path / "c.xml", tmp_path, "0")
    validate_cobertura(path)
    text = path.read_text()
    for broken in (text.replace(' hits="2"', ""), text.replace("<methods>", "<methods><x/>"),
                   text.replace("<sources>", "<sources>text")):
        path.write_text(broken)
        with pytest.raises(DtdError):
            validate_cobertura(path)
    assert ET.fromstring(text).get("lines-covered") == "2"
