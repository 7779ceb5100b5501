"""A log from whatever a user holds: a file path, a ROS bag, a pandas DataFrame, a pyarrow
Table, a mapping of column names to arrays, or a :class:`~fieldcal.logs.log.Log` already read.

:func:`read_log` is the library's entry to the same column recognition and checks the
``calibrate`` command applies to a file, so a notebook user gets what the CLI gets.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .log import Log, load_log
from .readers import Table

__all__ = ["read_log", "table_from_frame"]

#: The name a log given as a table in memory goes by in messages.
IN_MEMORY = "<table>"


def _column(values: object, name: str) -> NDArray[np.generic]:
    """One column of a frame as a 1-D numpy array: numbers as floats (missing values NaN),
    anything else as text."""
    to_numpy = getattr(values, "to_numpy", None)
    try:
        if to_numpy is not None:
            try:  # pandas' nullable dtypes: missing values become NaN, not pd.NA objects
                array = np.asarray(to_numpy(dtype=float, na_value=np.nan))
            except (TypeError, ValueError):
                array = np.asarray(to_numpy())
        else:
            array = np.asarray(values)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"column {name!r} cannot be read as an array ({exc}); give numbers"[:200]
        ) from None
    if array.ndim != 1:
        raise InputError(
            f"column {name!r} has shape {array.shape}; give one value per row (a 1-D column)"
        )
    if array.dtype.kind == "O":
        array = np.array(["" if v is None else str(v) for v in array], dtype=str)
    return array


def table_from_frame(frame: object) -> Table:
    """A :class:`Table` from a pandas DataFrame, a pyarrow Table or a mapping of names to
    1-D arrays (every column as long as the others)."""
    if isinstance(frame, Mapping):
        names = [str(k) for k in frame]
        columns = {str(k): _column(v, str(k)) for k, v in frame.items()}
    elif hasattr(frame, "column_names") and hasattr(frame, "column"):  # pyarrow.Table
        names = [str(n) for n in frame.column_names]
        columns = {
            n: _column(frame.column(i).to_numpy(zero_copy_only=False), n)
            for i, n in enumerate(names)
        }
    elif hasattr(frame, "columns") and hasattr(frame, "__getitem__"):  # pandas (or alike)
        names = [str(c) for c in frame.columns]
        if len(set(names)) != len(names):
            raise InputError("the DataFrame has repeated column names; give each its own name")
        columns = {str(c): _column(frame[c], str(c)) for c in frame.columns}
    else:
        raise InputError(
            f"cannot read a log from a {type(frame).__name__}; give a file path, a pandas "
            "DataFrame, a pyarrow Table, a mapping of column names to arrays, or a Log"
        )
    if not names:
        raise InputError("the table has no columns; give sensor columns such as ax,ay,az,mx,my,mz")
    lengths = {len(v) for v in columns.values()}
    if len(lengths) > 1:
        raise InputError(
            f"the table's columns have different lengths ({', '.join(map(str, sorted(lengths)))}"
            " rows); give one value per row in every column"
        )
    return Table(IN_MEMORY, names, columns)


def read_log(
    source: Log | str | os.PathLike[str] | object,
    *,
    accel_cols: str | Sequence[str] | None = None,
    mag_cols: str | Sequence[str] | None = None,
    gyro_cols: str | Sequence[str] | None = None,
    time_col: str | None = None,
    pose_col: str | None = None,
    drop_nan: bool = False,
    **reading: Any,
) -> Log:
    """Read a log and pick its sensor columns, as ``fieldcal calibrate`` does.

    Parameters
    ----------
    source : path, DataFrame, pyarrow Table, mapping or Log
        A file (CSV with a header, ``.npz``, ``.parquet``, a ROS bag), a table in memory, or a
        :class:`Log` (returned as it is).
    accel_cols, mag_cols, gyro_cols : "x,y,z" or three names, optional
        Explicit sensor columns; by default they are recognised by name.
    time_col, pose_col : str, optional
        Explicit time and pose-label columns (recognised by name by default).
    drop_nan : bool
        Drop rows with NaN or inf in a used column instead of refusing them.
    **reading
        Options of the file reader and of :func:`fieldcal.logs.log.load_log`: ``decimal``,
        ``split_on_reset``, ``imu_topic``, ``mag_topic``, ``on_progress``.

    Returns
    -------
    Log
        The sensor arrays (raw units, one row per kept sample), the time in seconds, the
        columns used and notes on the input.
    """
    if isinstance(source, Log):
        return source
    table = Path(source) if isinstance(source, str | os.PathLike) else table_from_frame(source)
    return load_log(
        table,
        accel_cols=accel_cols,
        mag_cols=mag_cols,
        gyro_cols=gyro_cols,
        time_col=time_col,
        pose_col=pose_col,
        drop_nan=drop_nan,
        **reading,
    )
