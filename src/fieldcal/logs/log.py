"""A log's sensor data: the columns picked, rows with missing values handled, time in seconds.

Every value a calibration cannot use is refused here, naming its row and column: NaN, inf or
an empty field (unless dropped), a reading beyond :data:`LARGEST`, one column read as two
things (two sensors, or a sensor and the time).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .columns import explicit_columns, normalise, recognise_columns
from .readers import Table, read_table

__all__ = ["LARGEST", "Log", "load_log"]

Array = NDArray[np.float64]

#: Largest reading accepted: its square (a covariance entry) must stay a finite float64. The
#: same limit as :data:`fieldcal.stats.poses.LARGEST` (a test keeps them equal), checked
#: here so the message can name the row and the column.
LARGEST = 1e150

_ROLE_NAMES = {
    "accel": "the accelerometer",
    "mag": "the magnetometer",
    "gyro": "the gyroscope",
    "time": "the time",
    "pose": "the pose labels",
}


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


def _time_in_seconds(values: Array, name: str, path: str = "") -> tuple[Array, str | None]:
    """Seconds from a time column in s, ms, µs or ns (from the name, else from the step)."""
    norm = normalise(name)
    scale = None
    for token, factor in (("ns", 1e-9), ("us", 1e-6), ("micros", 1e-6), ("ms", 1e-3)):
        if norm.endswith(token) or f"_{token}_" in norm or norm == token:
            scale = factor
    note = None
    with np.errstate(all="ignore"):  # a span beyond the float range is refused below
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
        seconds = (values - values[0]) * scale
    if not np.all(np.isfinite(seconds)):
        raise InputError(
            f"{path}: time column {name!r} spans more than floating point can hold; give the "
            "time in seconds (or choose another column with --time-col)"
        )
    return seconds, note


def _check_roles(path: str, used: dict[str, list[str]]) -> None:
    """One column cannot be two things (``--accel-cols mx,my,mz`` beside the recognised mag)."""
    owner: dict[str, str] = {}
    for role, cols in used.items():
        for c in cols:
            if c in owner and owner[c] != role:
                raise InputError(
                    f"{path}: column {c!r} is used for {_ROLE_NAMES[owner[c]]} and for "
                    f"{_ROLE_NAMES[role]}; give each its own columns (--accel-cols, --mag-cols, "
                    "--gyro-cols, --time-col, --pose-col)"
                )
            owner[c] = role
        if len(set(cols)) != len(cols):
            raise InputError(
                f"{path}: {_ROLE_NAMES[role]} columns {','.join(cols)} repeat a column; name "
                "three different columns x,y,z"
            )


def _check_values(
    table: Table, used: dict[str, list[str]], data: dict[str, Array], index: NDArray[np.int64]
) -> None:
    """Readings whose square overflows are refused, naming the first one's row and column
    (``index``: the data row of each kept row)."""
    for role, values in data.items():
        with np.errstate(invalid="ignore"):
            big = np.abs(values) > LARGEST
        if np.any(big):
            i, j = np.argwhere(big)[0]
            raise InputError(
                f"{table.path}: column {used[role][j]!r} has the value {values[i, j]:.3g} at "
                f"data row {index[i] + 1}; readings beyond {LARGEST:.0e} are too large to square "
                "in floating point: give them in a smaller unit (divide the column by a power of "
                "ten)"
            )


def _first_bad(values: dict[str, Array], names: dict[str, list[str]]) -> tuple[int, str]:
    """Data row (0-based) and column of the first NaN or inf."""
    best = (np.iinfo(np.int64).max, "")
    for role, array in values.items():
        bad = np.argwhere(~np.isfinite(array))
        if bad.size:
            i, j = bad[0]
            best = min(best, (int(i), names[role][j]))
    return best


def _listing(names: Sequence[str], limit: int = 12) -> str:
    shown = ", ".join(n if len(n) <= 30 else n[:30] + "..." for n in names[:limit])
    return shown + (f" ... ({len(names)} columns)" if len(names) > limit else "")


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
    if not isinstance(drop_nan, (bool, np.bool_)):
        raise InputError(f"drop_nan must be True or False, got {drop_nan!r}")
    if isinstance(need, str) or not all(role in ("accel", "mag", "gyro") for role in need):
        raise InputError(f"need must be a sequence of 'accel', 'mag', 'gyro'; got {need!r}")
    for label, name in (("time_col", time_col), ("pose_col", pose_col)):
        if name is not None and not isinstance(name, str):
            raise InputError(f"{label} must be a column name, got {name!r}")
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
                f"{_listing(table.names)}"
            )
        used[role] = cols
    _check_roles(table.path, used)
    if not any(role in used for role in need):
        raise InputError(
            f"{table.path}: no accelerometer or magnetometer columns recognised among "
            f"{_listing(table.names)}; name them ax,ay,az,mx,my,mz or pass --accel-cols/--mag-cols"
        )
    data: dict[str, Array] = {
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
        checked = dict(data)
        if time is not None:
            checked["time"] = time[:, None]
        row, column = _first_bad(checked, used)
        raise InputError(
            f"{table.path}: {n_bad} row(s) have NaN, inf or empty values (first at data row "
            f"{row + 1}, column {column!r}); pass --drop-nan to drop them, or clean the file"
        )
    index = np.flatnonzero(finite)
    if index.size == 0:
        raise InputError(
            f"{table.path}: no data rows"
            + (" left after dropping those with NaN, inf or empty values" if n_bad else "")
            + "; give a log with readings"
        )
    _check_values(table, used, {role: values[finite] for role, values in data.items()}, index)
    notes: list[str] = []
    if time is not None:
        time, note = _time_in_seconds(time[finite], used["time"][0], table.path)
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
