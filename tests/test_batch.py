"""``coolmuscle batch`` (docs/batch.md): golden transcripts side by side.

The transcripts in tests/data/batch/ were recorded from the manual's examples with
``coolmuscle run --record`` (2.1 operation example, 4.1.3 acceleration/deceleration,
6.3 loops); ``4.1.3-wrong-position.cml`` expects a wrong final position on purpose and
``6.3-loop-no-expectations.cml`` has no ``<<`` lines (it just runs).

The Dask test starts a real ``dask scheduler`` and two ``dask worker`` processes on
127.0.0.1 (ports chosen by the OS) and always stops them.
"""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import pytest

from cli_support import cli
from coolmuscle.tools.batch.engine import chunks
from dask_support import dask_cluster as dask_cluster_of
from fixtures import wait_until
from load_support import signal_and_wait

DATA = Path(__file__).parent / "data" / "batch"
SRC = Path(__file__).resolve().parent.parent / "src"
FAILING = DATA / "4.1.3-wrong-position.cml"
SCRIPTS = sorted(DATA.glob("*.cml"))


def junit_cases(path: Path) -> dict[str, ET.Element]:
    root = ET.parse(path).getroot()
    assert root.tag == "testsuites"
    (suite,) = root.findall("testsuite")
    return {case.get("name", ""): case for case in suite.findall("testcase")}


def run_check_failure(capsys: pytest.CaptureFixture[str], script: Path) -> str:
    """The first difference ``coolmuscle run --check`` reports for ``script``."""
    code, _, err = cli(capsys, "run", str(script), "--check")
    assert code == 1
    (line,) = [ln for ln in err.splitlines() if ln.startswith("coolmuscle: FAIL ")]
    return line.removeprefix("coolmuscle: FAIL ")


def test_batch_of_golden_transcripts_one_failing(capsys: pytest.CaptureFixture[str],
                                                 tmp_path: Path) -> None:
    junit = tmp_path / "junit.xml"
    code, out, err = cli(capsys, "batch", str(DATA), "--jobs", "2", "--junit", str(junit))
    assert code == 1
    first_difference = run_check_failure(capsys, FAILING)
    assert "Px.1=9999" in first_difference and "Px.1=10000" in first_difference
    cases = junit_cases(junit)
    assert sorted(cases) == sorted(str(p) for p in SCRIPTS)
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors"),
            suite.get("skipped")) == (str(len(SCRIPTS)), "1", "0", "0")
    for name, case in cases.items():
        failures = case.findall("failure")
        if name == str(FAILING):
            (failure,) = failures
            assert failure.get("message") == first_difference
            assert failure.text == first_difference
            assert failure.get("type") == "mismatch"
        else:
            assert not failures and not case.findall("error"), name
        assert float(case.get("time", "-1")) >= 0
    assert f"coolmuscle: FAIL {FAILING}: {first_difference}" in err
    assert re.search(rf"{len(SCRIPTS)} run\(s\): {len(SCRIPTS) - 1} passed, 1 failed", err)
    assert "FAIL" in out and "ran" in out  # the summary table: the one without '<<' ran


def test_passing_batch_exits_0_and_results_table(capsys: pytest.CaptureFixture[str],
                                                 tmp_path: Path) -> None:
    results = tmp_path / "results.csv"
    passing = [str(p) for p in SCRIPTS if p != FAILING]
    code, _, _ = cli(capsys, "batch", *passing, "--jobs", "1", "--results", str(results))
    assert code == 0
    import csv
    rows = list(csv.DictReader(results.open()))
    assert [r["script"] for r in rows] == passing
    status = {Path(r["script"]).name: r["status"] for r in rows}
    assert status["6.3-loop-no-expectations.cml"] == "ran"
    assert status["2.1-operation.cml"] == "pass"
    row = next(r for r in rows if r["script"].endswith("2.1-operation.cml"))
    # 2.1: P.1=10000 then |1 back to the origin; it arrives twice (Ux.1=8 twice)
    assert float(row["m1.final_position"]) == pytest.approx(0, abs=1e-6)
    assert float(row["m1.peak_speed"]) == pytest.approx(10000, abs=1e-6)  # S.1=100: 100 pps
    assert len(row["m1.in_position"].split(";")) == 2 and row["m1.alarms"] == ""
    # 0.2 s after the second in-position, which comes once Px is within K55 (5 pulses)
    # of 0 (ch. 3 K55), a little before the |1 command ends
    assert row["duration_s"] == "11.497406926"


def test_the_golden_transcripts_of_the_suite_pass_as_a_batch(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """tests/transcripts: '# chain: motors= firmware= machine= state=' headers honoured."""
    transcripts = Path(__file__).parent / "transcripts"
    code, _, err = cli(capsys, "batch", str(transcripts), "--jobs", "2")
    assert code == 0, err
    count = len(list(transcripts.glob("*.cml")))
    assert f"{count} run(s): {count} passed, 0 failed" in err


# -- Dask -----------------------------------------------------------------
def cluster(tmp_path: Path, workers: int) -> contextlib.AbstractContextManager[str]:
    """A scheduler and ``workers`` single-thread workers on 127.0.0.1, always stopped."""
    return dask_cluster_of(tmp_path, workers, dict(os.environ, PYTHONPATH=str(SRC)))


@pytest.fixture
def dask_cluster(tmp_path: Path) -> Iterator[str]:
    """A scheduler and two workers on 127.0.0.1 (ports chosen by the OS)."""
    with cluster(tmp_path, 2) as address:
        assert address.startswith("tcp://127.0.0.1:")
        yield address


def _worker_task_counts(address: str) -> list[int]:
    from distributed import Client
    with Client(address, timeout=10) as client:
        counts = client.run(lambda dask_worker: dask_worker.state.executed_count)
    return sorted(counts.values())


def _without_times(path: Path) -> str:
    return re.sub(r' time="[0-9.]+"', "", path.read_text())


def test_the_same_batch_through_dask_gives_the_same_results(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, dask_cluster: str) -> None:
    local_csv, local_xml = tmp_path / "local.csv", tmp_path / "local.xml"
    dask_csv, dask_xml = tmp_path / "dask.csv", tmp_path / "dask.xml"
    local = cli(capsys, "batch", str(DATA), "--jobs", "2", "--results", str(local_csv),
                "--junit", str(local_xml))
    before = sum(_worker_task_counts(dask_cluster))
    remote = cli(capsys, "batch", str(DATA), "--scheduler", dask_cluster,
                 "--results", str(dask_csv), "--junit", str(dask_xml))
    assert local[0] == remote[0] == 1
    assert "Dask scheduler" in remote[2] and "2 worker(s)" in remote[2]
    # the runs went to the workers: one task per part of the batch
    assert sum(_worker_task_counts(dask_cluster)) - before == len(chunks(len(SCRIPTS), 2))
    assert dask_csv.read_bytes() == local_csv.read_bytes()   # figures too, bit for bit
    assert _without_times(dask_xml) == _without_times(local_xml)
    failure = junit_cases(dask_xml)[str(FAILING)].find("failure")
    assert failure is not None and "Px.1=9999" in (failure.text or "")


# -- bad input: one line, exit 2, before anything runs ------------------------
@pytest.mark.parametrize("args, message", [
    (["batch", str(DATA / "2.1-operation.cml"), "missing.cml"], "missing.cml: no such script"),
    (["batch", str(DATA), "--jobs", "0"], "--jobs must be 1..256, not 0"),
    (["batch", str(DATA), "--jobs", "2", "--scheduler", "tcp://127.0.0.1:8786"],
     "--jobs and --scheduler exclude each other"),
    (["batch", str(DATA), "--results", "/nonexistent-dir/r.csv"], "does not exist"),
])
def test_bad_input_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str],
                                          tmp_path: Path, args: list[str],
                                          message: str) -> None:
    junit = tmp_path / "junit.xml"
    code, out, err = cli(capsys, *args, "--junit", str(junit))
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("coolmuscle: error: ") and message in err
    assert "Traceback" not in err and out == ""
    assert not junit.exists()  # nothing ran, nothing written


def test_unreachable_scheduler_is_one_line_exit_2_at_once(
        capsys: pytest.CaptureFixture[str], closed_port: int) -> None:
    address = f"tcp://127.0.0.1:{closed_port}"
    start = time.monotonic()
    code, out, err = cli(capsys, "batch", str(DATA), "--scheduler", address)
    assert code == 2 and out == ""
    assert err == f"coolmuscle: error: cannot reach the Dask scheduler at {address}: " \
                  "Connection refused\n"
    assert time.monotonic() - start < 5


def test_a_scheduler_without_workers_is_one_line_exit_2(
        capsys: pytest.CaptureFixture[str], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    from coolmuscle.tools.batch import engine as batchrun
    monkeypatch.setattr(batchrun, "WORKER_TIMEOUT", 0.5)
    with cluster(tmp_path, 0) as address:
        code, out, err = cli(capsys, "batch", str(DATA), "--scheduler", address)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert err.startswith(f"coolmuscle: error: the Dask scheduler at {address} has no "
                          "workers")


def test_a_bad_script_in_the_batch_stops_it_before_it_runs(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    bad = tmp_path / "bad.cml"
    bad.write_text("S.1=100\n@wiat 1\n")
    results = tmp_path / "r.csv"
    code, _, err = cli(capsys, "batch", str(DATA / "2.1-operation.cml"), str(bad),
                       "--results", str(results))
    assert code == 2 and "bad.cml: line 2: unknown directive @wiat" in err
    assert err.count("\n") == 1 and not results.exists()


def test_ctrl_c_stops_the_batch_and_reports_what_finished(tmp_path: Path) -> None:
    """SIGINT to the process group (as a terminal's Ctrl-C): exit 130, the finished runs
    reported and written, the rest 'not run', no traceback, no process left."""
    scripts = [DATA / "2.1-operation.cml", DATA / "6.3-loop.cml"]
    for i in range(6):  # long in virtual time: each takes about a second to trace
        slow = tmp_path / f"slow{i}.cml"
        slow.write_text("S.1=100\nP.1=5000\n^.1\n@wait 90\n")
        scripts.append(slow)
    results, junit = tmp_path / "r.csv", tmp_path / "j.xml"
    env = dict(os.environ, PYTHONPATH=str(SRC))
    proc = subprocess.Popen([sys.executable, "-m", "coolmuscle", "batch", *map(str, scripts),
                             "--jobs", "2", "--results", str(results), "--junit", str(junit)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    # once the pool's two workers exist (the runs are under way), as a user would
    wait_until(lambda: len(_group(proc.pid)) >= 4 or proc.poll() is not None, 60, 0.05)
    assert proc.poll() is None, proc.communicate()
    time.sleep(0.5)
    _, err = signal_and_wait(proc, group=True)
    text = err.decode()
    assert proc.returncode == 130, text
    assert "Traceback" not in text
    match = re.search(r"interrupted: (\d+) finished, (\d+) not run", text)
    assert match, text
    finished, not_run = int(match.group(1)), int(match.group(2))
    assert finished + not_run == len(scripts) and not_run > 0
    import csv
    rows = list(csv.DictReader(results.open()))
    assert sum(r["status"] == "not run" for r in rows) == not_run
    assert len(junit_cases(junit)) == len(scripts)
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None and suite.get("skipped") == str(not_run)
    # the pool's workers are gone; the forkserver and resource tracker follow their parent
    assert wait_until(lambda: not _group(proc.pid), 10, 0.1), \
        "processes of the batch are still running"


SLOW = "S.1=100\nP.1=5000\n^.1\n@wait 90\n"


def test_a_pool_stopped_by_ctrl_c_leaves_no_thread_of_its_own_running() -> None:
    """The cause of a traceback seen twice after Ctrl-C (``threading._shutdown`` ->
    ``atexit_call()`` -> ... "Bad file descriptor"): the pool was shut down without
    waiting, and its manager thread was still closing its wake-up pipe while the
    interpreter's exit hook wrote to it.  Once ``run`` has let the Ctrl-C through, every
    thread the pool started has ended."""
    from coolmuscle.tools.batch.engine import PoolEngine
    from coolmuscle.tools.batch.job import Job

    before = set(threading.enumerate())
    engine = PoolEngine(2)
    jobs = [Job(name="quick", script="?96.1\n")] + [Job(name=f"slow{i}", script=SLOW)
                                                      for i in range(4)]

    def ctrl_c(_index: int, _outcome: object) -> None:
        raise KeyboardInterrupt           # where a Ctrl-C lands: while runs are under way
    try:
        with pytest.raises(KeyboardInterrupt):
            engine.run(jobs, ctrl_c)
        left = [t.name for t in set(threading.enumerate()) - before if t.is_alive()]
    finally:
        engine.close()
    assert left == []


#: A batch's engine, then a Ctrl-C (``CTRL_C`` seconds after it exists) and an exit at
#: once, as soon as the engine is closed: the exit races with what the pool leaves.
ENGINE_THEN_EXIT = f"""
import sys
from coolmuscle.tools.batch.engine import PoolEngine
from coolmuscle.tools.batch.job import Job
engine = PoolEngine(2)
print("engine", flush=True)
try:
    engine.run([Job(name=str(i), script={SLOW!r}) for i in range(6)], lambda i, o: None)
except KeyboardInterrupt:
    pass
finally:
    try:
        engine.close()
    except KeyboardInterrupt:
        pass
print("stopped", file=sys.stderr)
"""


def test_ctrl_c_at_a_sweep_of_instants_of_a_pool_prints_nothing_more() -> None:
    """Ctrl-C to the process group (as a terminal sends it) at instants from the pool's
    creation on (its server loading the model, workers starting, runs under way): the
    program's own line is all stderr has, and no process of the group is left.  Before:
    the fork server's and the workers' KeyboardInterrupt tracebacks (they start with
    Python's default handler) and a worker's FileNotFoundError (started inside a submit
    the Ctrl-C cut short, it loaded its queue after the semaphores were gone)."""
    env = dict(os.environ, PYTHONPATH=str(SRC))
    for delay in (0.0, 0.1, 0.3, 0.7, 1.2):
        proc = subprocess.Popen([sys.executable, "-c", ENGINE_THEN_EXIT], env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
        assert proc.stdout is not None and proc.stdout.readline() == "engine\n"
        time.sleep(delay)
        _, err = signal_and_wait(proc, group=True, timeout=60)
        assert err == "stopped\n", (delay, err)
        assert wait_until(lambda pgid=proc.pid: not _group(pgid), 10, 0.1), \
            (delay, "processes of the pool are still running")


def _group(pgid: int) -> list[str]:
    """The processes of a process group (the batch, its forkserver and workers)."""
    found = subprocess.run(["pgrep", "-g", str(pgid)], capture_output=True, text=True)
    return found.stdout.split()


def test_the_chain_header_chooses_motors_firmware_and_a_state_directory(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """'# chain: motors=2 state=1' (as tests/transcripts use it): ID2 answers (1.1 daisy
    chain), '$' saves into a state directory of the run's own (2.1.2)."""
    script = tmp_path / "two.cml"
    script.write_text("# chain: motors=2 state=1\n?96.2\n<< ?96.2\\r\\n\n<< Px.2=0\\r\\n\n"
                      "$.1\n@wait 0.1\n")
    code, _, err = cli(capsys, "batch", str(script), "--results", str(tmp_path / "r.csv"))
    assert code == 1  # '$.1' answers something the transcript does not expect ...
    assert "after the last expectation the motor sent" in err
    header = tmp_path / "bad.cml"
    header.write_text("# chain: motorz=2\n?96.1\n")
    code, _, err = cli(capsys, "batch", str(header))
    assert code == 2 and "unknown '# chain:' key 'motorz'" in err
    script.write_text("# chain: motors=2 state=1\n?96.2\n<< ?96.2\\r\\n\n<< Px.2=0\\r\\n\n")
    code, _, err = cli(capsys, "batch", str(script))
    assert code == 0, err
    import csv
    rows = list(csv.DictReader((tmp_path / "r.csv").open()))
    assert rows[0]["m2.final_position"] == "0"  # the figures of motor 2 are there


@pytest.mark.parametrize("args, words", [
    (("--until", "inf"), "--until must be 0..1e+09 seconds, not inf"),
    (("--until", "1e300"), "--until must be 0..1e+09 seconds"),
    (("--scheduler", "tls://127.0.0.1:1"), "--scheduler tls://127.0.0.1:1: write tcp://HOST:PORT"),
    (("--scheduler", "inproc://x"), "--scheduler inproc://x: write tcp://HOST:PORT"),
    (("--results", "/dev/full"), "cannot write /dev/full: No space left on device"),
])
def test_batch_options_that_cannot_work_are_one_line(capsys: pytest.CaptureFixture[str],
                                                     tmp_path: Path, args: tuple[str, ...],
                                                     words: str) -> None:
    """An attack found: --until inf accepted and every run an error; tls:// and inproc://
    schedulers an internal error or a traceback after a 10 s stall; a full disk reported
    as "cannot write None".  Each is now one line and exit 2."""
    script = tmp_path / "s.cml"
    script.write_text("S.1=1\n")
    jobs = () if "--scheduler" in args else ("-j", "1")
    code, _out, err = cli(capsys, "batch", *jobs, *args, str(script))
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and words in lines[-1] and "Traceback" not in err, err
