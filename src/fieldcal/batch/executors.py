"""Where a batch's logs are calibrated: here, in local processes, or on a Dask cluster.

Each executor runs :func:`fieldcal.batch.job.run_task` on every task and yields the
:class:`~fieldcal.batch.job.JobResult` as each finishes (completion order; the batch puts the
rows back in the order of the logs).

- :func:`run_sequential`: in this process, one log after another.
- :func:`run_processes`: a pool of ``jobs`` processes started with ``spawn`` (safe with the
  threads a caller may have: a progress bar, a Dask client), each limited to one BLAS thread
  (the pool already uses every core). A worker that dies (killed for memory, a crash in a
  library) breaks the pool: the logs it was running are retried once, each alone in a fresh
  process, so a log that kills its worker again is the one to blame and gets a failed row;
  the logs that had not started go on in a new pool.
- :func:`run_dask`: on an existing Dask distributed cluster; tasks carry the log's path or URL
  and the workers read it (nothing big goes through the scheduler). ``retries=1``; a worker
  that dies is the scheduler's business (``distributed.scheduler.allowed-failures``), and a
  task it gives up on (``KilledWorker``) is a failed row.
"""

from __future__ import annotations

import collections
import concurrent.futures as cf
import importlib
import multiprocessing
import os
import socket
from collections.abc import Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from .._version import __version__
from ..errors import InputError
from .job import JobResult, Task, run_task
from .manifest import fallback_device
from .table import error_row

__all__ = ["BLAS_ENV", "default_jobs", "run_dask", "run_processes", "run_sequential"]

#: Environment variables that cap the thread pools of BLAS and OpenMP in a worker process.
BLAS_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")

#: Tasks in flight per worker process: enough to keep each busy, few to redo after a death.
_AHEAD = 2

_STARTED: Any = None


def default_jobs() -> int:
    """The cores this process may use (its CPU affinity where the system tells it).

    Returns
    -------
    int
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover  # macOS, Windows
        return max(1, os.cpu_count() or 1)


def run_sequential(tasks: Sequence[Task]) -> Iterator[JobResult]:
    """Every task in this process, in order.

    Parameters
    ----------
    tasks : sequence of Task

    Yields
    ------
    JobResult
    """
    for task in tasks:
        yield run_task(task)


# ----------------------------------------------------------------------------- processes
def _init_worker(started: Any) -> None:
    """A worker's start: one BLAS thread (the variables for libraries loaded later, the limit
    for those loaded already) and the flags saying which task it has begun."""
    global _STARTED
    _STARTED = started
    for name in BLAS_ENV:
        os.environ[name] = "1"
    importlib.import_module("threadpoolctl").threadpool_limits(1)


def _run_marked(task: Task) -> JobResult:
    """:func:`run_task`, flagging the task as begun first: when a worker dies, the flags tell
    the logs it was running from the ones still queued."""
    _STARTED[task.index] = 1
    return run_task(task)


def _died(task: Task, what: str) -> JobResult:
    return JobResult(
        task.index,
        error_row(
            task.device or fallback_device(task.log),
            task.log,
            f"{what} (killed for memory, or a crash in a library); calibrate it alone with "
            "`fieldcal calibrate` to see why",
            seconds=0.0,
            version=__version__,
        ),
    )


def _pool(jobs: int, started: Any) -> cf.ProcessPoolExecutor:
    return cf.ProcessPoolExecutor(
        max_workers=jobs,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_init_worker,
        initargs=(started,),
    )


def _alone(task: Task, started: Any) -> JobResult:
    """A retry in a fresh process of its own."""
    with _pool(1, started) as pool:
        try:
            return pool.submit(_run_marked, task).result()
        except BrokenProcessPool:
            return _died(task, "the worker process died twice calibrating this log")


def run_processes(tasks: Sequence[Task], jobs: int) -> Iterator[JobResult]:
    """Every task in a pool of ``jobs`` processes (see the module's docstring).

    Parameters
    ----------
    tasks : sequence of Task
        With distinct, non-negative ``index`` values.
    jobs : int
        Worker processes.

    Yields
    ------
    JobResult
        In completion order.
    """
    if not tasks:
        return
    context = multiprocessing.get_context("spawn")
    started = context.RawArray("b", max(t.index for t in tasks) + 1)
    queued = collections.deque(tasks)
    while queued:
        suspects: list[Task] = []
        pool = _pool(jobs, started)
        running: dict[cf.Future[JobResult], Task] = {}
        try:
            while queued or running:
                while queued and len(running) < _AHEAD * jobs:
                    task = queued.popleft()
                    running[pool.submit(_run_marked, task)] = task
                done, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
                broken = False
                for future in done:
                    task = running.pop(future)
                    try:
                        yield future.result()
                    except BrokenProcessPool:
                        broken = True
                        running[future] = task  # sorted out below with the others
                if broken:
                    break
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        # the pool broke: a log that was running may have killed it; the others go on
        for future, task in running.items():
            if future.done() and not future.cancelled() and future.exception() is None:
                yield future.result()
            elif started[task.index]:
                suspects.append(task)
            else:
                queued.appendleft(task)
        for task in sorted(suspects, key=lambda t: t.index):
            started[task.index] = 0
            yield _alone(task, started)


# ----------------------------------------------------------------------------- Dask
def _client(scheduler: object) -> tuple[Any, bool]:
    """A Dask client for ``scheduler`` (an address, or a client already made) and whether
    it was made here (and is closed here)."""
    try:
        distributed = importlib.import_module("distributed")
    except ImportError:
        raise InputError(
            "a Dask scheduler was given but dask.distributed is not installed; pip install "
            "'fieldcal[dask]'"
        ) from None
    if isinstance(scheduler, distributed.Client):
        return scheduler, False
    if not isinstance(scheduler, str) or not scheduler.strip():
        raise InputError(f"scheduler must be an address like tcp://HOST:8786, got {scheduler!r}")
    _check_address(scheduler.strip())
    try:
        client = distributed.Client(scheduler, timeout="20s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(
            f"could not connect to the Dask scheduler at {scheduler}: "
            f"{' '.join(str(exc).split())[:200]}; check the address (tcp://HOST:PORT)"
        ) from None
    return client, True


def _check_address(scheduler: str) -> None:
    """The address parsed and its scheduler reached (a TCP port tried, 5 s at most; an
    in-process one looked up) before a Dask client is made: a client that fails to connect
    waits twice its timeout when it is collected and prints a traceback from
    ``Client.__del__``, so a bad address never reaches one."""
    addressing = importlib.import_module("distributed.comm.addressing")
    shown = scheduler[:80]
    network = ("tcp", "tls", "ws", "wss")
    try:
        scheme, location = addressing.parse_address(scheduler)  # "HOST:PORT" is tcp
        host, port = addressing.parse_host_port(location) if scheme in network else ("", 0)
        if scheme not in (*network, "inproc", "ucx"):
            raise ValueError(f"unknown scheme {scheme!r}")
    except (ValueError, TypeError) as exc:
        raise InputError(
            f"scheduler must be an address like tcp://HOST:8786, got {shown!r} "
            f"({' '.join(str(exc).split())[:100]})"
        ) from None
    if scheme == "inproc":
        manager = importlib.import_module("distributed.comm.inproc").global_manager
        try:
            found = manager.get_listener_for(location)
        except (ValueError, AssertionError):
            found = None
        if found is None:
            raise InputError(
                f"no Dask scheduler in this process at {shown}; give a tcp://HOST:PORT address"
            )
        return
    if scheme not in network:
        return
    try:
        socket.create_connection((host, int(port)), timeout=5.0).close()
    except (OSError, ValueError, OverflowError) as exc:
        reason = getattr(exc, "strerror", None) or " ".join(str(exc).split())[:100]
        raise InputError(
            f"could not connect to the Dask scheduler at {shown}: {reason}; is it running? "
            "check the address (tcp://HOST:PORT)"
        ) from None


def run_dask(tasks: Sequence[Task], scheduler: object) -> Iterator[JobResult]:
    """Every task on a Dask distributed cluster (see the module's docstring).

    Parameters
    ----------
    tasks : sequence of Task
    scheduler : str or distributed.Client
        The scheduler's address (``tcp://HOST:PORT``) or a client.

    Yields
    ------
    JobResult
        In completion order.
    """
    if not tasks:
        return
    distributed = importlib.import_module("distributed")
    client, made = _client(scheduler)
    try:
        keys = [f"fieldcal-batch-{t.batch}-{t.index}" for t in tasks]
        futures = client.map(run_task, list(tasks), key=keys, retries=1, pure=False)
        by_key = {f.key: t for f, t in zip(futures, tasks, strict=True)}
        for future in distributed.as_completed(futures, loop=client.loop):
            task = by_key[future.key]
            try:
                result: JobResult = future.result()
            except Exception as exc:  # KilledWorker; fieldcal missing on the workers; ...
                if type(exc).__name__ == "KilledWorker":
                    result = _died(task, "the cluster gave up on this log: its workers died")
                else:
                    text = " ".join(str(exc).split())[:300]
                    result = JobResult(
                        task.index,
                        error_row(
                            task.device or fallback_device(task.log),
                            task.log,
                            f"{type(exc).__name__}: {text} (on the cluster: do its workers "
                            f"have fieldcal {__version__} and its dependencies?)",
                            seconds=0.0,
                            version=__version__,
                        ),
                    )
            future.release()
            yield result
    finally:
        if made:
            client.close()
