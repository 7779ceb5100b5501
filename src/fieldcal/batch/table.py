"""The batch's table: one row per log, its columns, and the files ``summary.csv`` and
``summary.parquet``.

The columns are fixed (:data:`COLUMNS`, types in :data:`COLUMN_TYPES`) whatever the logs hold,
so summaries of different batches concatenate: a value a log does not have (a gyroscope, an
error bar, everything for a log that failed) is empty in the CSV and null in Parquet. The
gains and biases are named as in the calibration's covariance (``accel.gain[0,1]``,
``mag.bias[2]``, :func:`fieldcal.comparison.parameter_values`), each followed by its standard
error (``accel.gain[0,1]_std``).
"""

from __future__ import annotations

import csv
import importlib
import importlib.util
import io
import math
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, TypeAlias

from .. import _files
from ..calibration import Calibration
from ..comparison import parameter_values

if TYPE_CHECKING:
    import pandas as pd
    import pyarrow as pa

__all__ = [
    "CODE_SEPARATOR",
    "COLUMNS",
    "COLUMN_TYPES",
    "PARAMETERS",
    "Cell",
    "SummaryRow",
    "error_row",
    "failed",
    "row_for",
    "to_arrow",
    "to_pandas",
    "write_summary",
]

#: The gains and biases of each sensor, named as in the covariance, in the table's order.
PARAMETERS: tuple[str, ...] = tuple(
    f"{sensor}.{name}"
    for sensor in ("accel", "mag", "gyro")
    for name in (
        *(f"gain[{j},{k}]" for j in range(3) for k in range(3)),
        *(f"bias[{j}]" for j in range(3)),
    )
)

#: Every column with its type: ``str``, ``int`` (nullable) or ``float`` (NaN when absent).
COLUMN_TYPES: dict[str, type] = {
    "device": str,
    "log": str,
    "verdict": str,  # pass | warn | fail; fail with `error` when the log gave no result
    "reasons": str,  # the verdict's reasons, " | " between them
    "reason_codes": str,  # their codes (docs/trust.md), "," between them: what scripts read
    "error": str,  # one line when the log could not be calibrated, else empty
    "export_error": str,  # one line when --export failed for a calibrated log, else empty
    "method": str,
    "samples": int,  # rows of the log used
    "n_poses": int,  # poses fitted
    "rejected_poses": int,  # poses the robust fit dropped
    "rejected": str,  # which and why, " | " between them
    "dip_deg": float,
    "dip_std_deg": float,
    "reference_dip_deg": float,  # the World Magnetic Model's at --location (NaN without one)
    "misalignment_deg": float,
    "misalignment_std_deg": float,
    "gravity_norm": float,  # |g| of the fit (1 unless --gravity)
    "field_strength": float,  # |h| of the fit (1 unless --field-strength)
    "accel_pose_noise": float,  # q of the accelerometer (raw units) and its standard error
    "accel_pose_noise_std": float,
    "mag_pose_noise": float,
    "mag_pose_noise_std": float,
    "tilt_deg": float,  # predicted accuracy (1σ, RMS over orientations)
    "heading_deg": float,
    "accel_norm_rel": float,
    "mag_norm_rel": float,
    "p_value": float,  # the fit certificate's
    **{name: float for p in PARAMETERS for name in (p, f"{p}_std")},
    "seconds": float,  # wall time of this log's work on its worker
    "fieldcal_version": str,
    "warnings": str,  # the library's warnings for this log, " | " between them
}

#: The columns in order.
COLUMNS: tuple[str, ...] = tuple(COLUMN_TYPES)

#: One cell of the table: text (``str`` columns), a count (``int`` columns, ``None`` when
#: absent) or a number (``float`` columns, NaN when absent).
Cell: TypeAlias = str | int | float | None
#: One log's row: every column of :data:`COLUMNS` by name.
SummaryRow: TypeAlias = dict[str, Cell]

_SEPARATOR = " | "
#: Between the codes of ``reason_codes``.
CODE_SEPARATOR = ","


def _number(value: float | None) -> float:
    return math.nan if value is None else float(value)


def _empty_row() -> SummaryRow:
    return {
        name: "" if kind is str else (None if kind is int else math.nan)
        for name, kind in COLUMN_TYPES.items()
    }


def row_for(
    cal: Calibration,
    *,
    device: str,
    log: str,
    samples: int,
    seconds: float,
    version: str,
    warned: Sequence[str] = (),
) -> SummaryRow:
    """The summary row of a calibration.

    Parameters
    ----------
    cal : Calibration
    device, log : str
        Its device id and the log as the batch named it.
    samples : int
        Rows of the log used.
    seconds : float
        Wall time of the log's work.
    version : str
        fieldcal's version on the worker.
    warned : sequence of str
        The library's warnings while calibrating it.

    Returns
    -------
    dict
        Every column of :data:`COLUMNS`.
    """
    row = _empty_row()
    verdict = cal.verdict
    values = parameter_values(cal)
    cov = cal.covariance
    for name in PARAMETERS:
        if name in values:
            row[name] = values[name]
            if cov is not None and name in cov.names:
                row[f"{name}_std"] = cov.std(name)
    for sensor in ("accel", "mag"):
        part = getattr(cal, sensor)
        if part is not None:
            row[f"{sensor}_pose_noise"] = part.pose_noise_std
            row[f"{sensor}_pose_noise_std"] = _number(part.pose_noise_std_se)
    acc = cal.accuracy
    if acc is not None:
        for name in ("tilt_deg", "heading_deg", "accel_norm_rel", "mag_norm_rel"):
            row[name] = _number(getattr(acc, name))
    row.update(
        device=device,
        log=log,
        verdict="fail" if verdict is None else verdict.level,
        reasons=_SEPARATOR.join(r.text for r in verdict.reasons) if verdict is not None else "",
        reason_codes=CODE_SEPARATOR.join(verdict.codes) if verdict is not None else "",
        method=cal.method,
        samples=int(samples),
        n_poses=cal.n_poses,
        rejected_poses=len(cal.rejected),
        rejected=_SEPARATOR.join(f"pose {r.index} ({r.sensor}): {r.reason}" for r in cal.rejected),
        dip_deg=_number(cal.dip_deg),
        dip_std_deg=_number(cal.dip_std_deg),
        reference_dip_deg=_number(
            None if cal.field_reference is None else cal.field_reference.dip_deg
        ),
        misalignment_deg=_number(cal.misalignment_deg),
        misalignment_std_deg=_number(cal.misalignment_std_deg),
        gravity_norm=_number(cal.gravity_norm),
        field_strength=_number(cal.field_strength),
        p_value=_number(None if cal.diagnostics is None else cal.diagnostics.p_value),
        seconds=float(seconds),
        fieldcal_version=version,
        warnings=_SEPARATOR.join(warned),
    )
    return row


def error_row(device: str, log: str, error: str, *, seconds: float, version: str) -> SummaryRow:
    """The row of a log that gave no calibration: verdict ``fail`` and the one-line ``error``.

    Parameters
    ----------
    device, log : str
    error : str
        One line: what went wrong and, where it can, the fix.
    seconds : float
    version : str

    Returns
    -------
    dict
    """
    row = _empty_row()
    row.update(
        device=device,
        log=log,
        verdict="fail",
        error=" ".join(error.split()) or "failed",
        seconds=float(seconds),
        fieldcal_version=version,
    )
    return row


def failed(row: Mapping[str, Cell]) -> bool:
    """Whether a row counts as a failure (verdict fail, an error, or an export not written).

    Parameters
    ----------
    row : mapping

    Returns
    -------
    bool
    """
    return row.get("verdict") == "fail" or bool(row.get("error")) or bool(row.get("export_error"))


# ----------------------------------------------------------------------------- files
def _cell(value: Cell) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)  # repr: the double, exactly
    return str(value)


def csv_text(rows: Sequence[Mapping[str, Cell]]) -> str:
    """The summary as CSV text (header, one line per row; empty cells for absent values)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in rows:
        writer.writerow([_cell(row.get(name)) for name in COLUMNS])
    return out.getvalue()


def _pyarrow() -> ModuleType:
    return importlib.import_module("pyarrow")


def to_arrow(rows: Sequence[Mapping[str, Cell]]) -> pa.Table:
    """The summary as a ``pyarrow.Table`` with the types of :data:`COLUMN_TYPES`.

    Parameters
    ----------
    rows : sequence of mapping

    Returns
    -------
    pyarrow.Table
    """
    pa = _pyarrow()
    kinds = {str: pa.string(), int: pa.int64(), float: pa.float64()}
    schema = pa.schema([(name, kinds[kind]) for name, kind in COLUMN_TYPES.items()])
    columns = {name: [row.get(name) for row in rows] for name in COLUMNS}
    for name, kind in COLUMN_TYPES.items():
        if kind is float:  # NaN (absent) as null, so readers see a missing value
            columns[name] = [
                None if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)
                for v in columns[name]
            ]
    return pa.Table.from_pydict(columns, schema=schema)


def to_pandas(rows: Sequence[Mapping[str, Cell]]) -> pd.DataFrame:
    """The summary as a ``pandas.DataFrame`` (NaN for absent numbers, ``<NA>`` for counts).

    Parameters
    ----------
    rows : sequence of mapping

    Returns
    -------
    pandas.DataFrame
    """
    pd = importlib.import_module("pandas")
    frame = pd.DataFrame([{name: row.get(name) for name in COLUMNS} for row in rows])
    frame = frame.reindex(columns=list(COLUMNS))
    for name, kind in COLUMN_TYPES.items():
        frame[name] = frame[name].astype(
            "Int64" if kind is int else ("float64" if kind is float else "string")
        )
    return frame


def write_summary(rows: Sequence[Mapping[str, Cell]], folder: Path) -> list[Path]:
    """Write ``summary.csv`` and ``summary.parquet`` into ``folder``, each atomically.

    Parameters
    ----------
    rows : sequence of mapping
    folder : Path

    Returns
    -------
    list of Path
        The files written (no Parquet file without pyarrow: a warning says so).
    """
    written = [folder / "summary.csv"]
    _files.write_text(written[0], csv_text(rows))
    if importlib.util.find_spec("pyarrow") is None:
        warnings.warn(
            "summary.parquet needs pyarrow, which is not installed; wrote summary.csv only "
            "(pip install 'fieldcal[parquet]')",
            stacklevel=2,
        )
        return written
    parquet = importlib.import_module("pyarrow.parquet")
    table = to_arrow(rows)
    with _files.replacing(folder / "summary.parquet") as temp:
        parquet.write_table(table, str(temp))
    written.append(folder / "summary.parquet")
    return written
