"""One log's work in a batch, as a plain top-level function any executor can run.

:func:`run_task` reads the log where it runs (a path on a shared file system or an fsspec URL:
the log never travels through a scheduler), calibrates it as ``fieldcal calibrate`` does,
writes ``<out>/<device>/cal.json`` and the exports asked for, each atomically, then
``row.json`` (the summary row; written last, it marks the log done for ``resume``), and
returns the row. Every error becomes a row with verdict ``fail`` and a one-line ``error``: a bad
log never stops a batch.

Everything written depends on the log and the options only (``created`` is the batch's, not
the worker's clock), so every executor writes byte-identical ``cal.json`` files; the wall time
goes into the summary row alone.

:func:`run_tasks` runs a worker's share of the logs (a chunk of up to :data:`GROUP`) in
threads taking turns, their Levenberg-Marquardt runs stepped together
(:mod:`fieldcal.likelihood.fleet`): the same work and the same files as :func:`run_task` on
each, the solver's fixed cost paid once per step for the chunk.

A device's folder is claimed by the log writing into it (``.owner.json``, created
exclusively): a second log of the same batch that names the same device gets an error row
instead of replacing the first one's files.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import importlib
import json
import math
import os
import secrets
import tempfile
import time
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING
from urllib.parse import urlparse

from .. import _files
from .._version import __version__
from ..calibration import Calibration
from ..errors import InputError
from ..likelihood.fleet import run_together
from ..likelihood.fleet import seconds as _clock
from ..logs import Log, PoseSet, load_log
from ..logs.arrow_parser import pyarrow_module
from ..output import exports as export_formats
from ..pipeline import LogSettings, document, run_log
from ..serialize import dumps
from ..settings import ReadSettings
from .manifest import device_id, fallback_device
from .table import COLUMN_TYPES, Cell, SummaryRow, error_row, row_for

if TYPE_CHECKING:
    import threadpoolctl

__all__ = [
    "CRASH_ENV",
    "GROUP",
    "JobResult",
    "Task",
    "export_name",
    "read_row",
    "run_task",
    "run_tasks",
]

#: Logs calibrated together by one worker (their LM runs stepped at once), at most.
GROUP = 64


#: Testing only: a log whose file name this variable lists (``a.csv,b.csv:once``) makes its
#: worker process die (``os._exit``), as an out-of-memory kill would; ``NAME:once`` dies on the
#: first attempt only (a marker ``<log>.crashed`` remembers it). Unset, it costs one lookup.
CRASH_ENV = "FIELDCAL_TEST_CRASH"

#: The files a log's folder holds besides its exports.
CAL_FILE, ROW_FILE, OWNER_FILE = "cal.json", "row.json", ".owner.json"


@dataclass(frozen=True)
class Task:
    """One log to calibrate, everything the worker needs (picklable).

    Attributes
    ----------
    index : int
        The log's place in the batch (the summary keeps this order).
    log : str
        Path or fsspec URL, read on the worker.
    device : str or None
        The device id a manifest gives; else the log's own, else its file stem.
    settings : LogSettings
        How to read and calibrate the log: the batch's options with the manifest row's in
        their place, built once (:meth:`fieldcal.pipeline.LogSettings.of`).
    out : str or None
        The batch's folder (on a file system every worker sees), or ``None`` to write nothing.
    exports : tuple of str
        Export formats to write beside ``cal.json``.
    created : str
        The ``created`` stamp of every calibration in the batch.
    batch : str
        A token naming this batch run (for the device folders' claims).
    force : bool
        A device folder holding another log's results from an earlier batch may be replaced.
    keep : bool
        Return the :class:`~fieldcal.calibration.Calibration` with the row.
    """

    index: int
    log: str
    device: str | None
    settings: LogSettings = field(default_factory=LogSettings)
    out: str | None = None
    exports: tuple[str, ...] = ()
    created: str = ""
    batch: str = ""
    force: bool = False
    keep: bool = True


@dataclass(frozen=True)
class JobResult:
    """What a task gives back: its summary row and, when kept, the calibration."""

    index: int
    row: SummaryRow
    calibration: Calibration | None = None


def export_name(fmt: str) -> str:
    """The file an export is written to in a device's folder: ``cal`` and the format's
    suffix (``cal.h``, ``cal.parm``), ``cal.export.json`` for the ``json`` format.

    Parameters
    ----------
    fmt : str
        A name in :data:`fieldcal.output.exports.FORMATS`.

    Returns
    -------
    str
    """
    suffix = export_formats.get(fmt).suffix
    return "cal.export.json" if suffix == ".json" else f"cal{suffix}"


# ----------------------------------------------------------------------------- reading
@contextlib.contextmanager
def _local_copy(url: str) -> Iterator[str]:
    """An fsspec URL's content in a temporary file with the same suffix (the readers pick the
    format by suffix); removed afterwards."""
    try:
        fsspec = importlib.import_module("fsspec")
    except ImportError:
        raise InputError(f"{url}: reading URLs needs fsspec; pip install fsspec") from None
    suffix = "".join(PurePosixPath(urlparse(url).path).suffixes[-2:])
    handle, name = tempfile.mkstemp(prefix="fieldcal-", suffix=suffix)
    try:
        with os.fdopen(handle, "wb") as target, fsspec.open(url, "rb") as source:
            while chunk := source.read(1 << 22):
                target.write(chunk)
        yield name
    finally:
        with contextlib.suppress(OSError):
            os.unlink(name)


def _read(log: str, read: ReadSettings) -> Log:
    reading = read.keywords()
    if "://" not in log:
        loaded: Log = load_log(log, **reading)
        return loaded
    with _local_copy(log) as local:
        copy: Log = load_log(local, **reading)
    # the log is named by its URL, not the temporary copy: cal.json says where it came from
    return dataclasses.replace(copy, path=log)


# ----------------------------------------------------------------------------- the work
_CONTROLLER: threadpoolctl.ThreadpoolController | None = None


def _blas_one_thread() -> contextlib.AbstractContextManager[object]:
    """One BLAS thread for this log's work: the executors run one log per core already. The
    controller is made once per process (scanning the loaded libraries takes milliseconds)."""
    global _CONTROLLER
    if _CONTROLLER is None:
        _CONTROLLER = importlib.import_module("threadpoolctl").ThreadpoolController()
    return _CONTROLLER.limit(limits=1)


def _crash_for_test(log: str) -> None:
    wanted = os.environ.get(CRASH_ENV)
    if not wanted:
        return
    modes = dict(entry.partition(":")[::2] for entry in wanted.split(","))
    mode = modes.get(PurePosixPath(log.replace("\\", "/")).name)
    if mode is None:
        return
    if mode == "once":
        marker = Path(f"{log}.crashed")
        if marker.exists():
            return
        marker.touch()
    os._exit(70)


def _message(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    if isinstance(exc, MemoryError):
        return "not enough memory for this log on its worker"
    if isinstance(exc, InputError):
        return text or "the log was refused"
    if isinstance(exc, OSError) and exc.filename and str(exc.filename) not in text:
        text = f"{exc.filename}: {text}"
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def run_task(task: Task) -> JobResult:
    """Calibrate one log and write its files: see the module's docstring.

    Parameters
    ----------
    task : Task

    Returns
    -------
    JobResult
        The row (verdict ``fail`` with ``error`` when the log gave no result).
    """
    return _finish(task, _calibrate(task))


@dataclass(frozen=True)
class _Calibrated:
    """A log read and calibrated, its files not yet written."""

    device: str
    samples: int
    calibration: Calibration
    poses: PoseSet
    warned: tuple[str, ...]
    seconds: float


def _failed(task: Task, device: str, exc: BaseException, seconds: float) -> JobResult:
    row = error_row(device, task.log, _message(exc), seconds=seconds, version=__version__)
    return JobResult(task.index, row)


def _calibrate(task: Task) -> _Calibrated | JobResult:
    """Read and calibrate the log (no file written); a failure is its row."""
    started = _clock()
    device = task.device or fallback_device(task.log)
    try:
        _crash_for_test(task.log)
        with _blas_one_thread(), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            log = _read(task.log, task.settings.read)
            if task.device is None and log.device is not None:
                device = device_id(log.device)
            run = run_log(log, task.settings)
        cal = dataclasses.replace(run.calibration, created=task.created or run.calibration.created)
        warned = [
            " ".join(str(w.message).split()) for w in caught if w.category is not RuntimeWarning
        ]
        return _Calibrated(
            device, log.n, cal, run.poses, tuple(dict.fromkeys(warned)), _clock() - started
        )
    except Exception as exc:  # any failure is this log's row; Ctrl-C still stops the batch
        return _failed(task, device, exc, _clock() - started)


def _finish(task: Task, done: _Calibrated | JobResult) -> JobResult:
    """Write the calibrated log's files and make its row."""
    if isinstance(done, JobResult):
        return done
    started = time.perf_counter()
    try:
        export_error = ""
        if task.out is not None:
            export_error = _write(
                task, done.device, done.calibration, document(done.calibration, done.poses)
            )
        row = row_for(
            done.calibration,
            device=done.device,
            log=task.log,
            samples=done.samples,
            seconds=done.seconds + time.perf_counter() - started,
            version=__version__,
            warned=list(done.warned),
        )
        row["export_error"] = export_error
        if task.out is not None:
            _files.write_text(Path(task.out) / done.device / ROW_FILE, _row_json(row))
        return JobResult(task.index, row, done.calibration if task.keep else None)
    except Exception as exc:  # any failure is this log's row; Ctrl-C still stops the batch
        return _failed(task, done.device, exc, done.seconds + time.perf_counter() - started)


def run_tasks(tasks: Sequence[Task], group: int = GROUP) -> list[JobResult]:
    """Calibrate a worker's logs together: :func:`run_task` on each, the calibrations in up
    to ``group`` threads whose LM runs are stepped together (see the module's docstring), the
    files then written in the order of the logs (a device two logs name is the first one's,
    as one at a time).

    Parameters
    ----------
    tasks : sequence of Task
    group : int
        Logs in flight at once (1: one after another, as :func:`run_task`).

    Returns
    -------
    list of JobResult
        In the order of ``tasks``; each row's ``seconds`` is the log's own time (its turns and
        its share of the stepped LM runs, then its files).
    """
    if len(tasks) > 1:
        # several logs: pyarrow's CSV reader pays its import back (the reader takes it for any
        # size once it is loaded, parsing a small log in about half numpy's time)
        pyarrow_module("pyarrow.csv")
    if group <= 1 or len(tasks) <= 1:
        return [run_task(task) for task in tasks]
    with _blas_one_thread():  # once for all: the threads' own limits then change nothing
        answers = run_together([functools.partial(_calibrate, task) for task in tasks], group)
    out = []
    for task, answer in zip(tasks, answers, strict=True):
        if isinstance(answer, (_Calibrated, JobResult)):
            out.append(_finish(task, answer))
        else:  # _calibrate returns every Exception as a row: this is what escaped it
            device = task.device or fallback_device(task.log)
            out.append(_failed(task, device, answer or RuntimeError("cancelled"), 0.0))
    return out


def _write(task: Task, device: str, cal: Calibration, doc: Mapping[str, object]) -> str:
    """Write ``cal.json`` and the exports; returns the exports' errors as one line (empty when
    every export was written): a failed export never hides the calibration's row."""
    folder = Path(str(task.out)) / device
    _claim(folder, device, task)
    # row.json goes last (run_task): without it the log counts as not done, so a batch killed
    # between two of these files redoes the log on --resume
    with contextlib.suppress(FileNotFoundError):
        (folder / ROW_FILE).unlink()
    _files.write_text(folder / CAL_FILE, dumps(doc) + "\n")  # as `fieldcal calibrate` writes it
    errors = []
    for fmt in task.exports:
        try:
            _files.write_bytes(folder / export_name(fmt), export_formats.export_bytes(cal, fmt))
        except (ValueError, OSError) as exc:  # InputError is a ValueError
            errors.append(f"{fmt}: {_message(exc)}")
    return " | ".join(errors)


# ----------------------------------------------------------------------------- device folders
def _claim(folder: Path, device: str, task: Task) -> None:
    """Make ``folder`` this log's, or refuse in one line when another log holds it."""
    folder.mkdir(parents=True, exist_ok=True)
    owner = folder / OWNER_FILE
    mine = json.dumps({"log": task.log, "batch": task.batch})
    for _ in range(3):
        # written whole to a temporary file, then linked: the claim appears complete or not
        # at all, and link fails when it exists (no two logs both win)
        temp = folder / f".owner.{secrets.token_hex(4)}.part"
        temp.write_text(mine, encoding="utf-8")
        try:
            os.link(temp, owner)
            return
        except FileExistsError:
            pass
        finally:
            temp.unlink()
        try:
            held = json.loads(owner.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue  # removed or replaced meanwhile: try again
        if held.get("log") == task.log:
            return
        if held.get("batch") == task.batch:
            raise InputError(
                f"device {device!r} is also named by {held.get('log')} in this batch; give "
                "each log its device in a manifest .csv (columns log,device)"
            )
        if not task.force:
            raise InputError(
                f"{folder} holds the results of {held.get('log')} from an earlier batch; give "
                "this log its own device in a manifest .csv, or --force to replace them"
            )
        with contextlib.suppress(FileNotFoundError):
            owner.unlink()
    raise InputError(f"{folder}: could not claim the device's folder; run the batch again")


# ----------------------------------------------------------------------------- rows on disk
def _row_json(row: Mapping[str, Cell]) -> str:
    clean = {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in row.items()}
    return dumps(clean, indent=1) + "\n"


def read_row(path: Path) -> SummaryRow | None:
    """A row written by :func:`run_task` (``row.json``), or ``None`` when it cannot be read.

    Parameters
    ----------
    path : Path

    Returns
    -------
    dict or None
        Every column of the summary (nulls back to NaN).
    """
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("log"), str):
        return None
    row: SummaryRow = {}
    for name, kind in COLUMN_TYPES.items():
        value = data.get(name)
        if kind is float:
            row[name] = math.nan if value is None else float(value)
        elif kind is int:
            row[name] = None if value is None else int(value)
        else:
            row[name] = "" if value is None else str(value)
    return row
