"""Many calibrations in threads of one process, their Levenberg-Marquardt runs stepped together.

:func:`run_together` runs jobs (one device's whole calibration each: reading, pose statistics,
starts, trust path, files) in ``width`` threads that take turns: one thread runs at a time,
until it calls :func:`.levenberg.levenberg_marquardt` or finishes a job. When every thread
waits at an LM run or has no job left, the runs are grouped by layout (:func:`.stacked.layout`)
and stepped together by :func:`.lockstep.lockstep`; each thread then gets its own result and
goes on, in the order of the threads. The pipeline is the same code as for one device: only
its LM runs meet.

Properties the batch relies on:

- **Identical results.** The lockstep kernel gives each run the single solver's result bit
  for bit, whoever else is in the group, and the turns are taken in a fixed order, so a job's
  result and its files do not depend on the grouping or the width.
- **No deadlock.** A thread whose job raises is that job's result (the exception); a thread
  that finishes leaves the group; the group steps whenever every remaining thread waits. An
  error in the kernel is the result of each run it held.
- **Warnings per job.** The threads take turns only at LM runs, and the ``warnings`` module's
  state (filters, ``showwarning``, a ``catch_warnings(record=True)`` list) is saved and restored
  at each turn, so a job's ``catch_warnings`` sees its own warnings only, as alone.
- **Time per job.** :func:`seconds` is, in a member thread, the time that thread held the turn
  plus its share of the kernel runs it waited for (elsewhere :func:`time.perf_counter`).
"""

from __future__ import annotations

import collections
import gc
import threading
import time
import warnings
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field
from typing import Generic, TypeAlias, TypeVar

import numpy as np

from .levenberg import SERVICE, Result, solve_alone
from .lockstep import Request, lockstep
from .pose_model import Problem, State
from .stacked import layout

__all__ = ["TOTALS", "Fleet", "run_together", "seconds"]

T = TypeVar("T")

#: The ``warnings`` module's state a thread sees: filters, showwarning, _showwarnmsg_impl.
_WARNING_STATE = ("filters", "showwarning", "_showwarnmsg_impl")


#: Those three values: the filters (a list, copied per thread) and two functions.
_WarningState: TypeAlias = tuple[list[object], object, object]


def _save_warnings() -> _WarningState:
    filters, show, show_impl = (getattr(warnings, name) for name in _WARNING_STATE)
    return filters, show, show_impl


def _restore_warnings(state: _WarningState) -> None:
    for name, value in zip(_WARNING_STATE, state, strict=True):
        setattr(warnings, name, value)
    warnings._filters_mutated()  # type: ignore[attr-defined]


@dataclass
class _Member:
    """One thread of the fleet: its place in the turn order, its warnings, its clock."""

    index: int
    warnings: _WarningState
    own: float = 0.0
    since: float = 0.0
    #: set when this thread holds the turn (only the next holder is woken, not every thread)
    turn: threading.Event = field(default_factory=threading.Event)


@dataclass
class _Call:
    """One LM run waiting for the group."""

    member: int
    request: Request
    result: Result | BaseException | None = None


_LOCAL = threading.local()
#: This process's fleets so far: kernel rounds, the LM runs they held, and their seconds
#: (for the benchmarks: the solver's time per device).
TOTALS = {"rounds": 0.0, "runs": 0.0, "seconds": 0.0}
#: One fleet at a time in a process (two would each swap the warnings state under the other).
_ONE_AT_A_TIME = threading.Lock()


def seconds() -> float:
    """A clock for one job's own time: in a fleet's thread, the time it held the turn plus its
    share of the kernel runs; elsewhere :func:`time.perf_counter`.

    Returns
    -------
    float
        Seconds from an arbitrary origin (differences only).
    """
    member: _Member | None = getattr(_LOCAL, "member", None)
    if member is None:
        return time.perf_counter()
    return member.own + (time.perf_counter() - member.since)


@dataclass
class Fleet(Generic[T]):
    """Threads taking turns, their LM runs stepped together (see the module's docstring)."""

    jobs: Sequence[Callable[[], T]]
    width: int
    results: list[T | BaseException | None] = field(init=False)
    _lock: threading.Lock = field(init=False, default_factory=threading.Lock)
    _ready: collections.deque[int] = field(init=False, default_factory=collections.deque)
    _waiting: dict[int, _Call] = field(init=False, default_factory=dict)
    _members: dict[int, _Member] = field(init=False, default_factory=dict)
    _next: int = field(init=False, default=0)
    cancelled: bool = field(init=False, default=False)
    #: kernel runs made and the LM runs they held (for the benchmarks)
    rounds: int = field(init=False, default=0)
    runs: int = field(init=False, default=0)
    kernel_seconds: float = field(init=False, default=0.0)

    def __post_init__(self) -> None:
        self.results = [None] * len(self.jobs)

    # ------------------------------------------------------------------ the threads
    def run(self) -> list[T | BaseException | None]:
        """Run every job; the results (or the exceptions they raised) in the jobs' order."""
        with _ONE_AT_A_TIME:
            return self._run()

    def _run(self) -> list[T | BaseException | None]:
        # Python's cycle collector is paused while the jobs run and then run once over what
        # they made: with a chunk's calibrations alive at once its periodic passes traverse
        # many more objects than one calibration's (measured: ~1 ms per Table 1 device)
        paused = gc.isenabled()
        gc.disable()
        try:
            return self._threads()
        finally:
            if paused:
                gc.enable()
                gc.collect(0)

    def _threads(self) -> list[T | BaseException | None]:
        base = _save_warnings()
        width = max(1, min(self.width, len(self.jobs)))
        threads = []
        for index in range(width):
            self._members[index] = _Member(index, (list(base[0]), *base[1:]))
            self._ready.append(index)
            threads.append(
                threading.Thread(
                    target=self._member, args=(index,), name=f"fieldcal-fleet-{index}", daemon=True
                )
            )
        try:
            for thread in threads:
                thread.start()
            with self._lock:
                self._dispatch()
            for thread in threads:
                while thread.is_alive():  # a timeout: Ctrl-C reaches this thread
                    thread.join(0.2)
        except BaseException:
            self.cancelled = True  # the threads finish the job they hold and stop
            raise
        finally:
            _restore_warnings(base)
        return self.results

    def _member(self, index: int) -> None:
        member = self._members[index]
        _LOCAL.member = member
        SERVICE.set(self._solve)
        self._wait_turn(member)
        try:
            while not self.cancelled and self._next < len(self.jobs):
                k = self._next  # only the thread holding the turn runs: no race
                self._next += 1
                try:
                    self.results[k] = self.jobs[k]()
                except BaseException as exc:  # the job's result; the others go on
                    self.results[k] = exc
        finally:
            self._stop_clock(member)
            with self._lock:
                self._dispatch()

    def _wait_turn(self, member: _Member) -> None:
        member.turn.wait()
        member.turn.clear()
        _restore_warnings(member.warnings)
        member.since = time.perf_counter()

    def _stop_clock(self, member: _Member) -> None:
        member.own += time.perf_counter() - member.since
        member.warnings = _save_warnings()

    # ------------------------------------------------------------------ LM runs
    def _solve(
        self,
        problem: Problem,
        state: State,
        max_iter: int,
        tol: float,
        lam: float,
        known_minimum: float | None,
    ) -> Result:
        """The service :func:`.levenberg.levenberg_marquardt` hands its run to."""
        member: _Member = _LOCAL.member
        call = _Call(member.index, Request(problem, state, max_iter, tol, lam, known_minimum))
        self._stop_clock(member)
        with self._lock:
            self._waiting[member.index] = call
            self._dispatch()
        self._wait_turn(member)
        if isinstance(call.result, BaseException):
            raise call.result
        assert call.result is not None
        return call.result

    def _dispatch(self) -> None:
        """Give the turn to the next thread; when none is ready, step the waiting runs
        together first. Called with the lock held by the thread giving up the turn."""
        if not self._ready and self._waiting:
            self._step()
        if self._ready:
            self._members[self._ready.popleft()].turn.set()

    def _step(self) -> None:
        calls = [self._waiting[k] for k in sorted(self._waiting)]
        self._waiting.clear()
        started = time.perf_counter()
        groups: dict[Hashable, list[_Call]] = {}
        for call in calls:
            groups.setdefault(layout(call.request.problem), []).append(call)
        for group in groups.values():
            answers: list[Result | BaseException]
            try:
                with np.errstate(all="ignore"):
                    if len(group) > 1:
                        answers = list(lockstep([c.request for c in group]))
                    else:
                        answers = _one(group[0])
            except BaseException as exc:  # every run of the group gets it; no thread hangs
                answers = [exc] * len(group)
            for c, answer in zip(group, answers, strict=True):
                c.result = answer
        spent = time.perf_counter() - started
        self.rounds += 1
        self.runs += len(calls)
        self.kernel_seconds += spent
        TOTALS["rounds"] += 1
        TOTALS["runs"] += len(calls)
        TOTALS["seconds"] += spent
        for call in calls:
            self._members[call.member].own += spent / len(calls)
            self._ready.append(call.member)


def _one(call: _Call) -> list[Result | BaseException]:
    """A run alone: the single solver (the same result as the kernel, at less cost)."""
    r = call.request
    try:
        return [solve_alone(r.problem, r.state, r.max_iter, r.tol, r.lam, r.known_minimum)]
    except np.linalg.LinAlgError as exc:
        return [exc]


def run_together(jobs: Sequence[Callable[[], T]], width: int) -> list[T | BaseException | None]:
    """Run ``jobs`` in ``width`` threads taking turns, their LM runs stepped together.

    Parameters
    ----------
    jobs : sequence of callables
        Each one device's work; run in order of the list as threads become free.
    width : int
        Threads (devices in flight): how many LM runs can be stepped together.

    Returns
    -------
    list
        Each job's return value, or the exception it raised, in the jobs' order.
    """
    return Fleet(jobs, width).run()
