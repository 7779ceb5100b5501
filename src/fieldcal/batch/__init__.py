"""Many logs at once: every log calibrated on its own, one table of results, nothing lost.

:func:`calibrate_many` is the library's form of ``fieldcal batch`` (``docs/batch.md``):
:mod:`~fieldcal.batch.manifest` turns paths, globs and manifests into logs with their devices
and options, :mod:`~fieldcal.batch.job` is one log's work (read on the worker, calibrate,
write ``<out>/<device>/cal.json`` atomically, return a summary row),
:mod:`~fieldcal.batch.executors` runs the jobs here, in processes or on a Dask cluster, and
:mod:`~fieldcal.batch.table` is the table (``summary.csv``, ``summary.parquet``).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import inspect
import os
import secrets
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from .. import api
from ..calibration import Calibration
from ..errors import InputError
from ..output import exports as export_formats
from ..pipeline import LogSettings
from ..settings import OPTIONS
from .executors import default_jobs, run_dask, run_processes, run_sequential
from .job import CAL_FILE, GROUP, ROW_FILE, JobResult, Task, export_name, read_row
from .manifest import LogSpec, check_devices, expand_logs
from .table import COLUMNS, Cell, SummaryRow, failed, to_arrow, to_pandas, write_summary

if TYPE_CHECKING:
    import pandas as pd
    import pyarrow as pa

__all__ = ["COLUMNS", "BatchResult", "LogSpec", "calibrate_many", "export_name"]

#: Keywords of :func:`calibrate_many` that are not calibration options.
_OWN = ("on_progress", "log", "accel", "mag", "self", "group")


@dataclass(frozen=True)
class BatchResult:
    """What a batch gives: the summary rows in the order of the logs, and the calibrations.

    Attributes
    ----------
    rows : tuple of dict
        One per log, every column of :data:`COLUMNS` (``docs/batch.md``).
    calibrations : dict of str to Calibration
        By log (as in the rows' ``log``), for the logs that gave one (resumed ones read back
        from their ``cal.json``); empty when the calibrations were not kept.
    files : tuple of Path
        The summary files written (none without ``out``).
    resumed : int
        How many rows an earlier batch made (``resume``).
    """

    rows: tuple[SummaryRow, ...]
    calibrations: dict[str, Calibration] = field(default_factory=dict)
    files: tuple[Path, ...] = ()
    resumed: int = 0

    @property
    def failed(self) -> tuple[SummaryRow, ...]:
        """The rows whose verdict is fail or whose log gave an error."""
        return tuple(r for r in self.rows if failed(r))

    @property
    def summary(self) -> pd.DataFrame | pa.Table:
        """The summary as a ``pandas.DataFrame``, or a ``pyarrow.Table`` without pandas."""
        try:
            return self.to_pandas()
        except ImportError:
            return self.to_arrow()

    def to_pandas(self) -> pd.DataFrame:
        """The summary as a ``pandas.DataFrame`` (needs pandas)."""
        return to_pandas(self.rows)

    def to_arrow(self) -> pa.Table:
        """The summary as a ``pyarrow.Table`` (needs pyarrow)."""
        return to_arrow(self.rows)


def _allowed_options() -> set[str]:
    """The option table's keywords and :func:`fieldcal.calibrate`'s."""
    names = set(OPTIONS) | {
        p.name
        for p in inspect.signature(api.calibrate).parameters.values()
        if p.kind is p.KEYWORD_ONLY or p.kind is p.POSITIONAL_OR_KEYWORD
    }
    return names - set(_OWN)


def _check_options(options: Mapping[str, object], exports: Sequence[str]) -> None:
    unknown = sorted(set(options) - _allowed_options())
    if unknown:
        raise InputError(
            f"unknown option(s) {', '.join(unknown)}; calibrate_many takes the options of "
            "fieldcal.calibrate_log"
        )
    for fmt in exports:
        try:
            export_formats.get(fmt)
        except ValueError as exc:
            raise InputError(str(exc)) from None


def _done_before(folder: Path) -> dict[str, SummaryRow]:
    """Rows of logs whose results a previous batch wrote in full (``row.json`` beside its
    ``cal.json``), by log."""
    done: dict[str, SummaryRow] = {}
    for path in sorted(folder.glob(f"*/{ROW_FILE}")):
        row = read_row(path)
        if row is None or row["error"] or row["export_error"]:
            continue  # not done, or an export is still to write
        if (path.parent / CAL_FILE).is_file():
            done.setdefault(str(row["log"]), row)
    return done


def _prepare(folder: Path, *, resume: bool, force: bool) -> None:
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder}: exists and is not a folder; give --out a folder")
    if not (resume or force) and folder.is_dir():
        held = next(folder.glob(f"*/{ROW_FILE}"), None) or next(folder.glob("summary.*"), None)
        if held is not None:
            raise InputError(
                f"{folder} holds the results of an earlier batch ({held.name}); pass --resume "
                "to keep them and calibrate the other logs, or --force to redo them"
            )
    folder.mkdir(parents=True, exist_ok=True)


def _absolute(spec: LogSpec) -> LogSpec:
    if "://" in spec.log:
        return spec
    # workers (other processes, other machines) do not share this process's folder
    return LogSpec(os.path.abspath(spec.log), spec.device, spec.options, spec.source)


@dataclass
class _Plan:
    """A batch under way: its logs, the folder, each log's summary row (``None``: not yet),
    the calibrations kept, and the tasks left to run (the logs a resumed batch did before are
    taken from the folder)."""

    specs: list[LogSpec]
    folder: Path | None
    rows: list[SummaryRow | None]
    calibrations: dict[str, Calibration]
    tasks: list[Task]
    keep: bool
    on_result: Callable[[Mapping[str, Cell]], None] | None

    @property
    def out(self) -> str | None:
        return None if self.folder is None else str(self.folder)

    def add(
        self, done: Mapping[str, SummaryRow], options: Mapping[str, object], common: Task
    ) -> None:
        """A task for each log not ``done`` before (``common``: what every task shares), the
        rows of those done taken as they were."""
        for i, spec in enumerate(self.specs):
            if spec.log in done:
                self.rows[i] = done[spec.log]
                if self.keep and self.folder is not None:
                    text = (self.folder / str(done[spec.log]["device"]) / CAL_FILE).read_text(
                        encoding="utf-8"
                    )
                    self.calibrations[spec.log] = Calibration.from_json(text)
                if self.on_result is not None:
                    self.on_result(done[spec.log])
                continue
            settings = LogSettings.of({**options, **spec.options})
            self.tasks.append(
                dataclasses.replace(
                    common, index=i, log=spec.log, device=spec.device, settings=settings
                )
            )

    def collect(self, results: Iterator[JobResult]) -> BatchResult:
        """Each result's row and calibration as it comes; on Ctrl-C the summary of what was
        done is written before stopping."""
        rows, folder = self.rows, self.folder
        files: list[Path] = []
        try:
            for result in results:
                rows[result.index] = result.row
                if result.calibration is not None:
                    self.calibrations[self.specs[result.index].log] = result.calibration
                if self.on_result is not None:
                    self.on_result(result.row)
        except KeyboardInterrupt:
            if folder is not None:  # what was done is kept: the summary of those, then stop
                # workers may have finished logs whose rows had not come back yet: on disk
                on_disk = _done_before(folder)
                for i, spec in enumerate(self.specs):
                    if rows[i] is None and spec.log in on_disk:
                        rows[i] = on_disk[spec.log]
                write_summary([r for r in rows if r is not None], folder)
            raise
        finished = tuple(r for r in rows if r is not None)
        if folder is not None:
            files = write_summary(finished, folder)
        skipped = len(self.specs) - len(self.tasks)
        return BatchResult(finished, self.calibrations, tuple(files), skipped)


def _results(
    tasks: list[Task], scheduler: object, jobs: int | None, group: int
) -> Iterator[JobResult]:
    """The tasks run by Dask's ``scheduler``, in this process (one job or one task), or in
    ``jobs`` processes (default :func:`~.executors.default_jobs`)."""
    if scheduler is not None:
        return run_dask(tasks, scheduler, group)
    if (jobs or default_jobs()) == 1 or len(tasks) <= 1:
        return run_sequential(tasks, group)
    return run_processes(tasks, min(jobs or default_jobs(), len(tasks)), group)


def calibrate_many(
    logs: str | os.PathLike[str] | Iterable[str | os.PathLike[str] | LogSpec],
    *,
    out: str | os.PathLike[str] | None = None,
    jobs: int | None = None,
    scheduler: object = None,
    exports: Sequence[str] = (),
    resume: bool = False,
    force: bool = False,
    created: str | None = None,
    keep_calibrations: bool = True,
    on_result: Callable[[Mapping[str, Cell]], None] | None = None,
    group: int = GROUP,
    **options: object,
) -> BatchResult:
    """Calibrate many logs, each on its own, with the same options: ``fieldcal batch``.

    Parameters
    ----------
    logs : path, URL, glob, manifest, or an iterable of them (or of :class:`LogSpec`)
        The logs (``docs/batch.md``): files or fsspec URLs (read by the workers), globs, and
        manifests (``.csv`` with a ``log`` column, optional ``device`` and per-log options).
    out : path, optional
        The folder for ``<device>/cal.json`` (and the exports, and ``row.json``) and
        ``summary.csv`` / ``summary.parquet``; on a file system every worker sees. Without
        it nothing is written.
    jobs : int, optional
        Local worker processes (default: the cores this process may use); 1 runs every log in
        this process.
    scheduler : str or distributed.Client, optional
        A Dask scheduler's address (``tcp://HOST:PORT``) or a client: the logs run on that
        cluster instead (``pip install 'fieldcal[dask]'``); ``jobs`` is then unused.
    exports : sequence of str
        Export formats (:data:`fieldcal.output.exports.FORMATS`) written beside each
        ``cal.json`` (:func:`fieldcal.batch.export_name`).
    resume : bool
        Skip the logs whose results ``out`` already holds in full, keeping their rows.
    force : bool
        Redo logs whose results ``out`` holds (without ``resume`` or ``force`` a folder with
        results is refused).
    created : str, optional
        The ``created`` stamp of every calibration (default: the batch's start, UTC), so
        ``cal.json`` does not depend on which worker made it, or when.
    keep_calibrations : bool
        Return the calibrations (memory: about 20 kB each) or only the rows.
    on_result : callable, optional
        Called with each row as its log finishes (resumed rows first), for progress; the
        logs calibrated together finish together.
    group : int
        Logs each worker calibrates together, at most: their Levenberg-Marquardt runs are
        stepped at once (:mod:`fieldcal.likelihood.fleet`), with the same results as one at a
        time; 1 calibrates one log after another.
    **options
        What :func:`fieldcal.calibrate_log` takes (columns, still detection, ``method``,
        ``gravity``, ``pose_noise``, ...); a manifest's per-log values override them.

    Returns
    -------
    BatchResult
        ``rows`` in the order of the logs; ``summary`` as a table; ``failed``.

    Raises
    ------
    InputError
        Before any work: a missing log, a malformed manifest, two logs of one device, an
        unknown option or export format, ``out`` with results and neither ``resume`` nor
        ``force``, an unreachable scheduler. A log that fails is a row, not an exception.

    Examples
    --------
    >>> result = fieldcal.calibrate_many("logs/*.csv", out="results", jobs=4)  # doctest: +SKIP
    >>> result.summary[["device", "verdict", "dip_deg", "dip_std_deg"]]  # doctest: +SKIP
    """
    many = [logs] if isinstance(logs, (str, os.PathLike, LogSpec)) else list(logs)
    specs = [_absolute(s) for s in expand_logs(many)]
    _check_options(options, exports)
    check_devices(specs)
    if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1):
        raise InputError(f"jobs must be a whole number of processes, at least 1; got {jobs!r}")
    if isinstance(group, bool) or not isinstance(group, int) or group < 1:
        raise InputError(f"group must be a whole number of logs, at least 1; got {group!r}")
    folder = None if out is None else Path(os.path.abspath(out))
    if folder is None and resume:
        raise InputError("resume needs the folder of the earlier batch; give out=FOLDER")
    done: dict[str, SummaryRow] = {}
    if folder is not None:
        _prepare(folder, resume=resume, force=force)
        done = _done_before(folder) if resume else {}
    stamp = created or _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat()
    plan = _Plan(specs, folder, [None] * len(specs), {}, [], keep_calibrations, on_result)
    batch = secrets.token_hex(6)
    common = Task(
        -1, "", None, LogSettings(), plan.out, (*exports,), stamp, batch, force, plan.keep
    )
    plan.add(done, options, common)
    return plan.collect(_results(plan.tasks, scheduler, jobs, group))
