"""A local Dask cluster for the tests and the benchmarks alike (plain Python, no pytest:
bench/ imports it too, with ``tests/`` on its path).  docs/batch.md "Dask".
"""

from __future__ import annotations

import contextlib
import json
import shutil
import subprocess
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import IO

from fixtures import wait_until


def dask_bin() -> str:
    """The ``dask`` command of this interpreter's environment."""
    found = shutil.which("dask", path=str(Path(sys.executable).parent))
    if found is None:
        raise RuntimeError("dask is a test dependency (pyproject.toml [test]): "
                           "pip install -e '.[test]'")
    return found


@contextlib.contextmanager
def dask_cluster(folder: Path, workers: int, env: Mapping[str, str]) -> Iterator[str]:
    """``dask scheduler`` and ``workers`` single-thread ``dask worker`` processes on
    127.0.0.1 (ports chosen by the OS), each writing to ``folder/dask-N.log``; yields
    the scheduler's address once every worker is up, and stops them all whatever
    happens (workers first: a worker whose scheduler is gone waits to reconnect)."""
    dask = dask_bin()
    scheduler_file = folder / "scheduler.json"
    logs: list[IO[str]] = [(folder / f"dask-{n}.log").open("w") for n in range(workers + 1)]
    procs: list[subprocess.Popen[bytes]] = []
    try:
        procs.append(subprocess.Popen(
            [dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
             "--scheduler-file", str(scheduler_file)],
            env=dict(env), stdout=logs[0], stderr=subprocess.STDOUT, start_new_session=True))
        def written() -> bool:
            return scheduler_file.exists() and bool(scheduler_file.read_text().strip())
        wait_until(lambda: written() or procs[0].poll() is not None, 60, 0.05)
        if not written():
            raise RuntimeError("the Dask scheduler did not start: "
                               + (folder / "dask-0.log").read_text()[-2000:])
        address = str(json.loads(scheduler_file.read_text())["address"])
        for log in logs[1:]:
            procs.append(subprocess.Popen(
                [dask, "worker", address, "--host", "127.0.0.1", "--nthreads", "1",
                 "--no-nanny", "--no-dashboard"],
                env=dict(env), stdout=log, stderr=subprocess.STDOUT, start_new_session=True))
        if workers:
            from distributed import Client
            with Client(address, timeout=30) as client:
                client.wait_for_workers(workers, timeout=60)
        yield address
    finally:
        for proc in reversed(procs):
            if proc.poll() is None:
                proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for log in logs:
            log.close()
