"""Where the runs of a batch happen: in this process, a local process pool, or Dask.

:func:`open_engine` checks everything that can be checked before a run starts (a bad
``--jobs``, dask not installed, a scheduler that cannot be reached) and raises
:class:`EngineError`; :meth:`Engine.run` then runs the jobs and calls ``on_done`` with
each :class:`~coolmuscle.tools.batch.job.Outcome` as it arrives (in completion order),
and returns the outcomes in job order (``None`` for runs a Ctrl-C left unfinished).

Every engine runs the same function, :func:`coolmuscle.tools.batch.job.execute`, on
the same plain-value job, so the outcomes are the same whichever engine ran them.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import logging
import multiprocessing
import os
import re
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from ...errors import CoolMuscleError
from ...needs import needs_extra
from .job import Job, Outcome, execute, execute_many

log = logging.getLogger(__name__)

OnDone = Callable[[int, Outcome], None]

#: The port of ``dask scheduler`` when an address names none.
DEFAULT_SCHEDULER_PORT = 8786

#: Most local processes (``--jobs``).
MAX_JOBS = 256

#: Most runs sent to a worker as one task.
MAX_CHUNK = 16

#: Seconds to wait for a Dask scheduler to answer before giving up (exit 2).
CONNECT_TIMEOUT = 5.0

#: Seconds to wait for a scheduler's first worker before giving up (exit 2).
WORKER_TIMEOUT = 5.0


class EngineError(CoolMuscleError, ValueError):
    """The runs cannot start: bad ``--jobs``, no dask, an unreachable scheduler."""


class Engine:
    """Runs jobs; :meth:`close` releases what it holds."""

    description = "this process"

    def run(self, jobs: Sequence[Job], on_done: OnDone) -> list[Outcome | None]:
        outcomes: list[Outcome | None] = [None] * len(jobs)
        for index, job in enumerate(jobs):
            outcomes[index] = outcome = execute(job)
            on_done(index, outcome)
        return outcomes

    def close(self) -> None:
        return None


def _ignore_sigint() -> None:
    """Pool workers leave Ctrl-C to the parent, which stops them (no traceback each)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


class PoolEngine(Engine):
    """A ``concurrent.futures`` process pool of ``jobs`` processes on this machine."""

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self.description = f"{jobs} local processes"
        # forkserver: workers fork from a clean server that has imported the runner, not
        # from this process (whose progress-bar thread a fork would copy mid-lock).
        # Windows has no fork: there each worker is a new interpreter (spawn)
        try:
            context: Any = multiprocessing.get_context("forkserver")
        except ValueError:
            context = multiprocessing.get_context("spawn")
        else:
            context.set_forkserver_preload(["coolmuscle.tools.batch.job", "coolmuscle.chain"])
            # the server (and so every worker forked from it) starts with Ctrl-C blocked:
            # a terminal's Ctrl-C reaches the whole process group, and the server's first
            # second (its own start-up, the preload) has Python's default handler: a
            # KeyboardInterrupt traceback on the user's terminal
            # (the resource tracker first: starting it unblocks SIGINT again)
            from multiprocessing import forkserver, resource_tracker

            resource_tracker.ensure_running()
            with sigint_held(block=True):
                forkserver.ensure_running()
        self.pool = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=context,
                                           initializer=_ignore_sigint)

    def run(self, jobs: Sequence[Job], on_done: OnDone) -> list[Outcome | None]:
        outcomes: list[Outcome | None] = [None] * len(jobs)
        try:
            # a Ctrl-C inside submit (which starts the workers) left a worker the pool
            # never learnt of: it failed to load its queue, whose semaphores were gone,
            # with a traceback; held, it lands after the submits, and every worker stops
            with sigint_held():
                futures = {self.pool.submit(execute_many, [jobs[i] for i in part]): part
                           for part in chunks(len(jobs), self.jobs)}
            for future in cf.as_completed(futures):
                for index, outcome in zip(futures[future], future.result()):
                    outcomes[index] = outcome
                    on_done(index, outcome)
        except BaseException:
            self._stop()
            raise
        return outcomes

    def _stop(self) -> None:
        """Ctrl-C: end the running runs now, drop the queued ones, and wait until the
        pool's threads have ended (a thread still closing its pipes when the interpreter
        exits raced with Python's exit hook: "Bad file descriptor" with a traceback)."""
        # the executor has no public way to end a running task; its processes are ours
        processes = list((getattr(self.pool, "_processes", None) or {}).values())
        with sigint_held():
            for process in processes:
                if process.is_alive():
                    process.terminate()
            self.pool.shutdown(wait=True, cancel_futures=True)

    def close(self) -> None:
        """Wait for the pool's processes and threads to end (a Ctrl-C meanwhile is
        held until they have: it must not leave a thread behind)."""
        with sigint_held():
            self.pool.shutdown(wait=True)


@contextlib.contextmanager
def sigint_held(block: bool = False) -> Iterator[None]:
    """Ctrl-C (SIGINT) is held back inside: a handler that only notes it, then, once
    the block is done, the signal again for the handler that was there before (a
    ``KeyboardInterrupt`` from Python's default one).  ``block`` also blocks the
    signal in this thread, so that processes started inside inherit it blocked.
    Outside the main thread (no signal handlers there) it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, _frame: came.append(signum))
    # (Windows has no signal masks: nothing is blocked there, nor forked)
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) \
        if block and hasattr(signal, "pthread_sigmask") else None
    try:
        yield
    finally:
        if mask is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)   # a pending one: noted now
        signal.signal(signal.SIGINT, previous)
        if came:
            signal.raise_signal(signal.SIGINT)


class DaskEngine(Engine):
    """The runs as tasks on a Dask distributed cluster (``dask scheduler``/``worker``)."""

    def __init__(self, address: str) -> None:
        probe_scheduler(address)
        with needs_extra("dask", "--scheduler (Dask)"):
            from distributed import Client
        self.address = address
        try:
            self.client: Any = Client(address, timeout=CONNECT_TIMEOUT,
                                      set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise EngineError(f"cannot reach the Dask scheduler at {address}: "
                              f"{_short(exc)}") from None
        try:
            self.client.wait_for_workers(1, timeout=WORKER_TIMEOUT)
        except (OSError, TimeoutError) as exc:
            self.client.close()
            raise EngineError(f"the Dask scheduler at {address} has no workers (start "
                              f"'dask worker {address}'): {_short(exc)}") from None
        workers = len(self.client.scheduler_info().get("workers", {}))
        self.description = f"Dask scheduler {address} ({workers} worker(s) now)"

    def run(self, jobs: Sequence[Job], on_done: OnDone) -> list[Outcome | None]:
        from distributed import as_completed

        outcomes: list[Outcome | None] = [None] * len(jobs)
        workers = max(len(self.client.scheduler_info().get("workers", {})), 1)
        parts = chunks(len(jobs), workers)
        tag = f"{os.getpid()}-{id(jobs)}-{time.monotonic_ns()}"
        futures = [self.client.submit(execute_many, [jobs[i] for i in part], pure=False,
                                      key=f"coolmuscle-runs-{n}-{tag}")
                   for n, part in enumerate(parts)]
        part_of = {future.key: part for future, part in zip(futures, parts)}
        try:
            for future in as_completed(futures, loop=self.client.loop):
                for index, outcome in zip(part_of[future.key], future.result()):
                    outcomes[index] = outcome
                    on_done(index, outcome)
        except BaseException:
            self.client.cancel(futures)
            raise
        return outcomes

    def close(self) -> None:
        self.client.close()


def probe_scheduler(address: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """Fail at once (not after the client's retries) when nothing listens at a
    ``tcp://HOST:PORT`` address.  Only TCP is taken: ``tls://`` needs certificates the
    command line cannot give, ``inproc://`` is a scheduler inside one process, and
    either left the Dask client to fail after a 10 s stall with a traceback."""
    match = re.fullmatch(r"(?:tcp://)?(\[[^\]]+\]|[^:/\[\]]+)(?::(\d+))?/?", address)
    if match is None:
        raise EngineError(f"--scheduler {address}: write tcp://HOST:PORT")
    host = match.group(1).strip("[]")
    port = int(match.group(2) or DEFAULT_SCHEDULER_PORT)
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        raise EngineError(f"cannot reach the Dask scheduler at {address}: "
                          f"{exc.strerror or exc}") from None


def chunks(count: int, workers: int) -> list[range]:
    """The job indices in parts of a task each: about 8 parts per worker, at most
    ``MAX_CHUNK`` runs a part, so short runs do not pay one task's overhead each."""
    size = max(1, min(MAX_CHUNK, count // (workers * 8)))
    return [range(start, min(start + size, count)) for start in range(0, count, size)]


def _short(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def default_jobs() -> int:
    """The CPU count this process may use."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def open_engine(jobs: int | None, scheduler: str | None, runs: int | None = None) -> Engine:
    """The engine for ``--jobs`` / ``--scheduler`` (raises :class:`EngineError`); no more
    local processes than ``runs``, and none for a single run."""
    if scheduler is not None:
        if jobs is not None:
            raise EngineError("--jobs and --scheduler exclude each other (the cluster's "
                              "workers decide how many runs go at once)")
        if not scheduler.strip():
            raise EngineError("--scheduler needs an address, e.g. tcp://127.0.0.1:8786")
        return DaskEngine(scheduler.strip())
    count = default_jobs() if jobs is None else jobs
    if not 1 <= count <= MAX_JOBS:
        raise EngineError(f"--jobs must be 1..{MAX_JOBS}, not {count}")
    if runs is not None:
        count = max(min(count, runs), 1)
    return Engine() if count == 1 else PoolEngine(count)
