"""A log's sensor data: the columns picked, rows with missing values handled, time in seconds."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .columns import explicit_columns, normalise, recognise_columns
from .readers import read_table

__all__ = ["Log", "load_log"]

Array = NDArray[np.float64]


@dataclass
class Log:
    """A log's sensor data, ready for still detection and calibration.

    ``index`` maps each kept row to its data-row number in the file (rows with NaN are dropped
    only with ``drop_nan=True``), so segment boundaries are reported as the user sees them.
    """

    path: str
    accel: Array | None
    mag: Array | None
    gyro: Array | None
    time: Array | None
    pose: NDArray[np.generic] | None
    index: NDArray[np.int64]
    used: dict[str, list[str]]
    names: list[str]
    dropped: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.index)


def _time_in_seconds(values: Array, name: str) -> tuple[Array, str | None]:
    """Seconds from a time column in s, ms, µs or ns (from the name, else from the step)."""
    norm = normalise(name)
    scale = None
    for token, factor in (("ns", 1e-9), ("us", 1e-6), ("micros", 1e-6), ("ms", 1e-3)):
        if norm.endswith(token) or f"_{token}_" in norm or norm == token:
            scale = factor
    note = None
    if scale is None:
        steps = np.diff(values)
        step = float(np.median(steps)) if steps.size else 0.0
        # a sensor log between 0.5 Hz and 100 kHz: steps ≥ 1e5 are ns, ≥ 2 are ms
        if step >= 1e5:
            scale, note = 1e-9, f"time column {name!r} read as nanoseconds"
        elif step >= 2:
            scale, note = 1e-3, f"time column {name!r} read as milliseconds"
        else:
            scale = 1.0
    return (values - values[0]) * scale, note


def load_log(
    path: str | Path,
    *,
    accel_cols: str | Sequence[str] | None = None,
    mag_cols: str | Sequence[str] | None = None,
    gyro_cols: str | Sequence[str] | None = None,
    time_col: str | None = None,
    pose_col: str | None = None,
    drop_nan: bool = False,
    need: Sequence[str] = ("accel", "mag"),
) -> Log:
    """Read a log and pick its sensor columns.

    Parameters
    ----------
    accel_cols, mag_cols, gyro_cols : "x,y,z" names or a sequence of three, optional
        Explicit columns; by default they are recognised by name (see :func:`recognise_columns`).
    time_col, pose_col : str, optional
        Explicit time (seconds, or ms/µs/ns recognised from the name or step) and pose-label
        columns; ``time``/``t``/``timestamp`` and ``pose``/``label`` are recognised by default.
    drop_nan : bool
        Drop rows with NaN or inf in a used column instead of refusing them.
    need : sequence of str
        The roles of which at least one must be found (by default accelerometer or magnetometer).
    """
    table = read_table(path)
    guessed = recognise_columns(table.names)
    explicit = {
        "accel": explicit_columns(accel_cols),
        "mag": explicit_columns(mag_cols),
        "gyro": explicit_columns(gyro_cols),
        "time": None if time_col is None else [time_col],
        "pose": None if pose_col is None else [pose_col],
    }
    used: dict[str, list[str]] = {}
    for role in ("accel", "mag", "gyro", "time", "pose"):
        cols = explicit[role] if explicit[role] is not None else guessed.get(role)
        if cols is None:
            continue
        missing = [c for c in cols if c not in table.columns]
        if missing:
            raise InputError(
                f"{table.path}: no column {missing[0]!r} (for {role}); columns found: "
                f"{', '.join(table.names)}"
            )
        used[role] = cols
    if not any(role in used for role in need):
        raise InputError(
            f"{table.path}: no accelerometer or magnetometer columns recognised among "
            f"{', '.join(table.names)}; name them ax,ay,az,mx,my,mz or pass --accel-cols/--mag-cols"
        )
    data = {
        role: np.column_stack([table.numeric(c) for c in used[role]])
        for role in ("accel", "mag", "gyro")
        if role in used
    }
    time = table.numeric(used["time"][0]) if "time" in used else None
    pose = table.columns[used["pose"][0]] if "pose" in used else None

    finite = np.ones(table.n_rows, dtype=bool)
    for values in data.values():
        finite &= np.all(np.isfinite(values), axis=1)
    if time is not None:
        finite &= np.isfinite(time)
    n_bad = int(np.count_nonzero(~finite))
    if n_bad and not drop_nan:
        first = int(np.flatnonzero(~finite)[0]) + 1
        raise InputError(
            f"{table.path}: {n_bad} row(s) have NaN, inf or empty values in the sensor columns "
            f"(first at data row {first}); pass --drop-nan to drop them, or clean the file"
        )
    index = np.flatnonzero(finite)
    notes: list[str] = []
    if time is not None:
        time, note = _time_in_seconds(time[finite], used["time"][0])
        if note:
            notes.append(note)
    return Log(
        path=table.path,
        accel=data["accel"][finite] if "accel" in data else None,
        mag=data["mag"][finite] if "mag" in data else None,
        gyro=data["gyro"][finite] if "gyro" in data else None,
        time=time,
        pose=None if pose is None else pose[finite],
        index=index,
        used=used,
        names=table.names,
        dropped=n_bad,
        notes=notes,
    )
