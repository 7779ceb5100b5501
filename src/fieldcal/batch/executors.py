"""Where a batch's logs are calibrated: here, in local processes, or on a Dask cluster.

Each executor runs :func:`fieldcal.batch.job.run_tasks` on chunks of the tasks (up to
``group`` logs, calibrated together in one worker with their Levenberg-Marquardt runs stepped
at once: :mod:`fieldcal.likelihood.fleet`) and yields the
:class:`~fieldcal.batch.job.JobResult` of each log as its chunk finishes (completion order; the
batch puts the rows back in the order of the logs). ``group=1`` runs one log per task.

- :func:`run_sequential`: in this process, one chunk after another.
- :func:`run_processes`: a pool of ``jobs`` processes started with ``spawn`` (safe with the
  threads a caller may have: a progress bar, a Dask client), each limited to one BLAS thread
  (the pool already uses every core). A worker that dies (killed for memory, a crash in a
  library) breaks the pool: the logs it was running (its whole chunk) are retried once, each
  alone in a fresh process, so a log that kills its worker again is the one to blame and gets
  a failed row; the logs that had not started go on in a new pool.
- :func:`run_dask`: on an existing Dask distributed cluster; tasks carry the log's path or URL
  and the workers read it (nothing big goes through the scheduler). ``retries=1``; a worker
  that dies is the scheduler's business (``distributed.scheduler.allowed-failures``); the logs
  of a chunk it gives up on (``KilledWorker``) are tried again, each alone, and a log it gives
  up on alone is a failed row.
"""

from __future__ import annotations

import collections
import concurrent.futures as cf
import importlib
import math
import multiprocessing
import os
import socket
from collections.abc import Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from typing import TYPE_CHECKING, Any

from .._version import __version__
from ..errors import InputError
from .job import GROUP, JobResult, Task, run_tasks
from .manifest import fallback_device
from .table import error_row

if TYPE_CHECKING:
    import ctypes

    #: One flag per task index, shared with the worker processes: 1 once a worker began it.
    Started = ctypes.Array[ctypes.c_byte]

__all__ = [
    "BLAS_ENV",
    "chunks",
    "default_jobs",
    "run_dask",
    "run_processes",
    "run_sequential",
]

#: Environment variables that cap the thread pools of BLAS and OpenMP in a worker process.
BLAS_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")

#: Tasks in flight per worker process: enough to keep each busy, few to redo after a death.
_AHEAD = 2

_STARTED: Started | None = None


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


#: Log bytes (on disk) a chunk holds at most: the logs of a chunk are in memory at once.
CHUNK_BYTES = 64 << 20


def _size(task: Task) -> int:
    """The log's size on disk (0 for a URL or a log that cannot be seen from here)."""
    if "://" in task.log:
        return 0
    try:
        return os.path.getsize(task.log)
    except OSError:
        return 0


def chunks(
    tasks: Sequence[Task], group: int, workers: int, budget: int = CHUNK_BYTES
) -> list[tuple[Task, ...]]:
    """The tasks cut in chunks of at most ``group`` logs and ``budget`` bytes of logs (a chunk's
    logs are in memory at once: a large log goes alone), at least one chunk per worker when
    there are enough tasks (so no worker idles while another holds two chunks' worth).

    Parameters
    ----------
    tasks : sequence of Task
    group : int
        Logs calibrated together, at most (at least 1).
    workers : int
        Workers that run chunks at the same time.
    budget : int
        Bytes of log files in a chunk, at most (a log larger than that is a chunk alone).

    Returns
    -------
    list of tuple of Task
        In the tasks' order.
    """
    size = max(1, min(group, math.ceil(len(tasks) / max(1, workers))))
    out: list[tuple[Task, ...]] = []
    chunk: list[Task] = []
    held = 0
    for task in tasks:
        bytes_ = _size(task) if size > 1 else 0
        if chunk and (len(chunk) == size or held + bytes_ > budget):
            out.append(tuple(chunk))
            chunk, held = [], 0
        chunk.append(task)
        held += bytes_
    if chunk:
        out.append(tuple(chunk))
    return out


def run_sequential(tasks: Sequence[Task], group: int = GROUP) -> Iterator[JobResult]:
    """Every task in this process, ``group`` logs at a time calibrated together.

    Parameters
    ----------
    tasks : sequence of Task
    group : int
        Logs calibrated together (1: one after another).

    Yields
    ------
    JobResult
        In the tasks' order.
    """
    for chunk in chunks(tasks, group, 1):
        yield from run_tasks(chunk, group)


# ----------------------------------------------------------------------------- processes
def _init_worker(started: Started) -> None:
    """A worker's start: one BLAS thread (the variables for libraries loaded later, the limit
    for those loaded already) and the flags saying which task it has begun."""
    global _STARTED
    _STARTED = started
    for name in BLAS_ENV:
        os.environ[name] = "1"
    importlib.import_module("threadpoolctl").threadpool_limits(1)


def _run_marked(chunk: tuple[Task, ...], group: int) -> list[JobResult]:
    """:func:`run_tasks`, flagging the tasks as begun first: when a worker dies, the flags
    tell the logs it was running from the ones still queued."""
    assert _STARTED is not None  # set by _init_worker, the pool's initializer
    for task in chunk:
        _STARTED[task.index] = 1
    return run_tasks(chunk, group)


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


def _pool(jobs: int, started: Started) -> cf.ProcessPoolExecutor:
    return cf.ProcessPoolExecutor(
        max_workers=jobs,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_init_worker,
        initargs=(started,),
    )


def _alone(task: Task, started: Started) -> JobResult:
    """A retry in a fresh process of its own."""
    with _pool(1, started) as pool:
        try:
            return pool.submit(_run_marked, (task,), 1).result()[0]
        except BrokenProcessPool:
            return _died(task, "the worker process died twice calibrating this log")


def run_processes(tasks: Sequence[Task], jobs: int, group: int = GROUP) -> Iterator[JobResult]:
    """Every task in a pool of ``jobs`` processes (see the module's docstring).

    Parameters
    ----------
    tasks : sequence of Task
        With distinct, non-negative ``index`` values.
    jobs : int
        Worker processes.
    group : int
        Logs calibrated together in a worker, at most.

    Yields
    ------
    JobResult
        In completion order.
    """
    if not tasks:
        return
    context = multiprocessing.get_context("spawn")
    started = context.RawArray("b", max(t.index for t in tasks) + 1)
    # chunks of half a worker's share: the pool keeps _AHEAD per worker in flight
    queued = collections.deque(chunks(tasks, group, _AHEAD * jobs))
    while queued:
        suspects: list[Task] = []
        pool = _pool(jobs, started)
        running: dict[cf.Future[list[JobResult]], tuple[Task, ...]] = {}
        try:
            while queued or running:
                while queued and len(running) < _AHEAD * jobs:
                    chunk = queued.popleft()
                    running[pool.submit(_run_marked, chunk, group)] = chunk
                done, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
                broken = False
                for future in done:
                    chunk = running.pop(future)
                    try:
                        yield from future.result()
                    except BrokenProcessPool:
                        broken = True
                        running[future] = chunk  # sorted out below with the others
                if broken:
                    break
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        # the pool broke: a log that was running may have killed it; the others go on
        for future, chunk in running.items():
            if future.done() and not future.cancelled() and future.exception() is None:
                yield from future.result()
                continue
            for task in chunk:
                if started[task.index]:
                    suspects.append(task)
                else:
                    queued.appendleft((task,))
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


def _lost(task: Task, exc: Exception) -> JobResult:
    """The row of a log whose Dask task failed."""
    if type(exc).__name__ == "KilledWorker":
        return _died(task, "the cluster gave up on this log: its workers died")
    text = " ".join(str(exc).split())[:300]
    return JobResult(
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


def run_dask(tasks: Sequence[Task], scheduler: object, group: int = GROUP) -> Iterator[JobResult]:
    """Every task on a Dask distributed cluster (see the module's docstring).

    Parameters
    ----------
    tasks : sequence of Task
    scheduler : str or distributed.Client
        The scheduler's address (``tcp://HOST:PORT``) or a client.
    group : int
        Logs calibrated together in a task, at most.

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
        try:
            threads = sum(client.nthreads().values())
        except Exception:  # an older or unusual client: chunks of the full size
            threads = 1
        parts = chunks(tasks, group, max(1, threads))
        keys = [f"fieldcal-batch-{c[0].batch}-{c[0].index}" for c in parts]
        futures = client.map(run_tasks, parts, group=group, key=keys, retries=1, pure=False)
        by_key = {f.key: c for f, c in zip(futures, parts, strict=True)}
        pending = distributed.as_completed(futures, loop=client.loop)
        for future in pending:
            chunk = by_key.pop(future.key)
            try:
                results: list[JobResult] = future.result()
            except Exception as exc:  # KilledWorker; fieldcal missing on the workers; ...
                results = [_lost(task, exc) for task in chunk]
                if len(chunk) > 1 and type(exc).__name__ == "KilledWorker":
                    # one log of the chunk may be the killer: each again, alone
                    for task in chunk:
                        key = f"fieldcal-batch-{task.batch}-{task.index}-alone"
                        alone = client.submit(run_tasks, (task,), 1, key=key, retries=1, pure=False)
                        by_key[alone.key] = (task,)
                        pending.add(alone)
                    results = []
            future.release()
            yield from results
    finally:
        if made:
            client.close()
