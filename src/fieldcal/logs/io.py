"""Reading log files: CSV (with a header), NPZ and Parquet; which columns hold which sensor.

A log is a table with one row per sample. :func:`load_log` finds the accelerometer,
magnetometer and gyroscope columns under their common spellings (``ax``, ``acc_x``,
``accel_x``, ``grav_x``, ``ax_g``, ``mag_x``, ``mx_rawdiv10``, ``gyr_x``, ROS's
``field.linear_acceleration.x`` ...), an optional time column and an optional pose-label column,
and says which it used. Every problem is an :class:`~fieldcal.errors.InputError` whose message
names the problem and the fix.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError

__all__ = [
    "Log",
    "Table",
    "apply_to_file",
    "load_log",
    "parse_axes",
    "read_table",
    "recognise_columns",
]

Array = NDArray[np.float64]

# Prefix spellings per sensor, longest first so "accel_x" is not read as "a" + "ccel_x".
_PREFIXES: dict[str, tuple[str, ...]] = {
    "accel": (
        "field_linear_acceleration",
        "linear_acceleration",
        "accelerometer",
        "acceleration",
        "gravity",
        "accel",
        "grav",
        "acc",
        "a",
    ),
    "mag": (
        "field_magnetic_field",
        "magnetic_field",
        "magnetometer",
        "compass",
        "magn",
        "mag",
        "m",
    ),
    "gyro": (
        "field_angular_velocity",
        "angular_velocity",
        "gyroscope",
        "omega",
        "gyro",
        "gyr",
        "g",
        "w",
    ),
}
_SENSOR_RE = {
    sensor: re.compile(rf"^(?P<prefix>{'|'.join(p)})_?(?P<axis>[xyz])(?P<suffix>_.*)?$")
    for sensor, p in _PREFIXES.items()
}
_TIME_RE = re.compile(
    r"^(?:t|time|timestamp|stamp|field_header_stamp|sec|secs|seconds|millis|micros|elapsed)"
    r"(?:_.*)?$"
)
_POSE_NAMES = ("pose", "pose_id", "pose_label", "label")


def _normalise(name: str) -> str:
    """``"Acc X (m/s^2)"`` -> ``"acc_x_m_s_2"``: lower case, runs of other characters -> ``_``."""
    return re.sub(r"[^a-z0-9]+", "_", name.strip().lower()).strip("_")


# --------------------------------------------------------------------------- tables
@dataclass
class Table:
    """Columns of a log as read: numeric columns as float arrays, others as string arrays."""

    path: str
    names: list[str]
    columns: dict[str, np.ndarray]

    @property
    def n_rows(self) -> int:
        return 0 if not self.names else len(self.columns[self.names[0]])

    def numeric(self, name: str) -> Array:
        """Column ``name`` as floats; a one-line error naming the first non-numeric value."""
        values = self.columns[name]
        if values.dtype.kind == "f":
            return values
        if values.dtype.kind in "iub":
            return values.astype(float)
        return _to_float(values, name, self.path)


def _to_float(values: np.ndarray, name: str, path: str, first_row: int = 0) -> Array:
    text = np.char.strip(values.astype(str))
    text = np.where(text == "", "nan", text)  # an empty field is a missing value, not text
    try:
        return text.astype(float)
    except ValueError:
        bad = next(i for i, v in enumerate(text) if not _is_number(v))
        raise InputError(
            f"{path}: column {name!r} has a non-numeric value {str(text[bad])!r} at data row "
            f"{first_row + bad + 1}; fix or remove that row (or choose other columns)"
        ) from None


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _sniff_delimiter(header: str) -> str | None:
    for delimiter in (",", ";", "\t"):
        if delimiter in header:
            return delimiter
    return None  # whitespace-separated


def _data_lines(handle: TextIO) -> Iterator[str]:
    """Lines that are not blank and not ``#`` comments (loggers often write banners)."""
    for line in handle:
        if line.strip() and not line.lstrip().startswith("#"):
            yield line


def _split(lines: Sequence[str], delimiter: str | None) -> list[list[str]]:
    if delimiter is None:
        return [line.split() for line in lines]
    return list(csv.reader(lines, delimiter=delimiter))


def _read_csv(path: Path) -> Table:
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            lines = list(_data_lines(handle))
    except UnicodeDecodeError:
        raise InputError(
            f"{path}: not a text file; give a CSV with a header line (or .npz / .parquet)"
        ) from None
    if not lines:
        raise InputError(f"{path}: the file is empty; give a CSV with a header line and data rows")
    delimiter = _sniff_delimiter(lines[0])
    rows = _split(lines, delimiter)
    header = [h.strip() for h in rows[0]]
    if all(_is_number(h) for h in header):
        raise InputError(
            f"{path}: the first line is numbers, not a header; add a header line naming the "
            "columns, e.g. 't,ax,ay,az,mx,my,mz'"
        )
    body = rows[1:]
    if not body:
        raise InputError(f"{path}: the file has a header but no data rows")
    widths = np.fromiter((len(r) for r in body), dtype=np.int64, count=len(body))
    ragged = np.flatnonzero(widths != len(header))
    if ragged.size:
        i = int(ragged[0])
        raise InputError(
            f"{path}: data row {i + 1} has {widths[i]} fields but the header has {len(header)}; "
            f"fix the row ({ragged.size} such row(s)) or cut the file"
        )
    cells = np.array(body, dtype=str)
    columns: dict[str, np.ndarray] = {}
    for j, name in enumerate(header):
        column = np.char.strip(cells[:, j])
        filled = np.where(column == "", "nan", column)
        try:
            columns[name] = filled.astype(float)
        except ValueError:
            columns[name] = column  # text (labels, device names); checked when used
    return Table(str(path), header, columns)


def _read_npz(path: Path) -> Table:
    columns: dict[str, np.ndarray] = {}
    with np.load(path, allow_pickle=False) as data:
        for key in data.files:
            array = np.asarray(data[key])
            if array.ndim == 2 and array.shape[1] == 3:
                # an (n, 3) array named like a sensor becomes three columns "<name>_x" ...
                for axis, column in zip("xyz", array.T, strict=True):
                    columns[f"{key}_{axis}"] = column
            elif array.ndim == 1:
                columns[key] = array
    if not columns:
        raise InputError(
            f"{path}: no 1-D columns or (n, 3) arrays in the .npz; save e.g. accel=(n, 3), "
            "mag=(n, 3), t=(n,)"
        )
    lengths = {len(v) for v in columns.values()}
    if len(lengths) > 1:
        raise InputError(f"{path}: arrays of different lengths {sorted(lengths)}; save equal rows")
    return Table(str(path), list(columns), columns)


def _read_parquet(path: Path) -> Table:
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise InputError(
            f"{path}: reading Parquet needs pyarrow; pip install 'fieldcal[parquet]' or give a CSV"
        ) from None
    table = pq.read_table(path)
    columns = {
        name: table.column(name).to_numpy(zero_copy_only=False) for name in table.schema.names
    }
    for name, values in columns.items():
        if values.dtype.kind == "O":
            columns[name] = values.astype(str)
    return Table(str(path), list(columns), columns)


def read_table(path: str | Path) -> Table:
    """Read a CSV (header line, ``,`` ``;`` tab or blank separated), ``.npz`` or ``.parquet``."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file; check the path")
    if path.is_dir():
        raise InputError(f"{path}: is a folder; give the log file inside it")
    suffix = path.suffix.lower()
    try:
        if suffix == ".npz":
            return _read_npz(path)
        if suffix in (".parquet", ".pq"):
            return _read_parquet(path)
        return _read_csv(path)
    except InputError:
        raise
    except (OSError, ValueError) as exc:
        raise InputError(
            f"{path}: cannot read it ({exc}); give a readable CSV, .npz or .parquet"
        ) from None


# --------------------------------------------------------------------------- columns
def recognise_columns(names: Sequence[str]) -> dict[str, list[str]]:
    """Guess each role's columns from their names.

    Returns a dict with keys among ``accel``, ``mag``, ``gyro`` (three names each, x, y, z),
    ``time`` and ``pose`` (one name each). The first complete x/y/z triple of a sensor in column
    order wins (``ax_g, ay_g, az_g`` share a prefix and a suffix).
    """
    found: dict[str, list[str]] = {}
    for sensor, pattern in _SENSOR_RE.items():
        groups: dict[tuple[str, str], dict[str, str]] = {}
        for name in names:
            match = pattern.match(_normalise(name))
            if match:
                key = (match["prefix"], match["suffix"] or "")
                groups.setdefault(key, {}).setdefault(match["axis"], name)
        for axes in groups.values():
            if len(axes) == 3:
                found[sensor] = [axes["x"], axes["y"], axes["z"]]
                break
    for name in names:
        if "time" not in found and _TIME_RE.match(_normalise(name)):
            found["time"] = [name]
        if "pose" not in found and _normalise(name) in _POSE_NAMES:
            found["pose"] = [name]
    return found


def _explicit(spec: str | Sequence[str] | None) -> list[str] | None:
    if spec is None:
        return None
    names = [s.strip() for s in spec.split(",")] if isinstance(spec, str) else list(spec)
    if len(names) != 3 or not all(names):
        raise InputError(f"give three column names x,y,z, e.g. 'ax,ay,az'; got {spec!r}")
    return names


def parse_axes(spec: str) -> Array:
    """A signed axis map like ``"+y+x-z"`` as the 3x3 matrix ``P`` with ``mapped = P @ raw``.

    Output axis ``i`` is the ``i``-th term: ``"+y+x-z"`` maps ``(x, y, z)`` to ``(y, x, −z)``
    (the convention of sap6's ``axes`` strings). A missing sign means ``+``.
    """
    text = spec.strip().lower()
    terms = re.findall(r"([+-]?)([xyz])", text)
    if "".join(s + a for s, a in terms) != text or len(terms) != 3:
        raise InputError(
            f"axis map {spec!r} is not three signed axes; write e.g. '+y+x-z' (output x = raw y, "
            "output y = raw x, output z = −raw z)"
        )
    if sorted(a for _, a in terms) != ["x", "y", "z"]:
        raise InputError(f"axis map {spec!r} must use each of x, y and z once, e.g. '+x-y-z'")
    P = np.zeros((3, 3))
    for i, (sign, axis) in enumerate(terms):
        P[i, "xyz".index(axis)] = -1.0 if sign == "-" else 1.0
    return P


# --------------------------------------------------------------------------- logs
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
    pose: np.ndarray | None
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
    norm = _normalise(name)
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
        "accel": _explicit(accel_cols),
        "mag": _explicit(mag_cols),
        "gyro": _explicit(gyro_cols),
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


# --------------------------------------------------------------------------- apply
def _format(values: Array) -> np.ndarray:
    return np.char.mod("%.9g", values)


def apply_to_file(
    cal: Any,
    src: str | Path,
    dst: str | Path,
    *,
    accel_cols: str | Sequence[str] | None = None,
    mag_cols: str | Sequence[str] | None = None,
    chunk_rows: int = 50_000,
) -> dict[str, list[str]]:
    """Append calibrated columns (``<col>_cal``) to a log and write it to ``dst`` as CSV.

    CSV input is streamed ``chunk_rows`` rows at a time, so files larger than memory work; each
    input line is copied unchanged and the calibrated values follow it. Rows with a missing
    value give ``nan``. Returns the columns used per sensor.
    """
    src, dst = Path(src), Path(dst)
    if dst.resolve() == src.resolve():
        raise InputError(f"{dst}: is the input log itself; write the output to another file")
    sensors = [s for s in ("accel", "mag") if getattr(cal, s) is not None]
    if src.suffix.lower() in (".npz", ".parquet", ".pq"):
        return _apply_table(cal, read_table(src), dst, sensors, accel_cols, mag_cols)
    if not src.exists() or src.is_dir():
        raise InputError(f"{src}: no such file; check the path")
    try:
        return _apply_csv(cal, src, dst, sensors, accel_cols, mag_cols, chunk_rows)
    except UnicodeDecodeError:
        raise InputError(f"{src}: not a text file; give a CSV with a header line") from None


def _apply_csv(
    cal: Any,
    src: Path,
    dst: Path,
    sensors: list[str],
    accel_cols: str | Sequence[str] | None,
    mag_cols: str | Sequence[str] | None,
    chunk_rows: int,
) -> dict[str, list[str]]:
    with src.open(newline="", encoding="utf-8-sig") as handle:
        lines = _data_lines(handle)
        header_line = next(lines, None)
        if header_line is None:
            raise InputError(f"{src}: the file is empty; give a CSV with a header line")
        delimiter = _sniff_delimiter(header_line)
        header = [h.strip() for h in _split([header_line], delimiter)[0]]
        used = _columns_for_apply(str(src), header, sensors, accel_cols, mag_cols)
        where = {s: [header.index(c) for c in cols] for s, cols in used.items()}
        out_delim = delimiter or " "  # keep the input's separator
        new_names = [f"{c}_cal" for s in used for c in used[s]]
        row_number = 0
        with dst.open("w", newline="", encoding="utf-8") as out:
            out.write(out_delim.join([*header, *new_names]) + "\n")
            while True:
                chunk = [line for _, line in zip(range(chunk_rows), lines, strict=False)]
                if not chunk:
                    break
                rows = _split(chunk, delimiter)
                blocks = []
                for sensor, idx in where.items():
                    try:
                        raw = np.array([[r[i] for i in idx] for r in rows], dtype=str)
                    except IndexError:
                        raise InputError(
                            f"{src}: a row near data row {row_number + 1} has too few fields; "
                            "fix the file"
                        ) from None
                    values = np.column_stack(
                        [
                            _to_float(raw[:, k], used[sensor][k], str(src), row_number)
                            for k in range(3)
                        ]
                    )
                    fix = cal.correct_accel if sensor == "accel" else cal.correct_mag
                    blocks.append(_format(fix(values)))
                appended = np.concatenate(blocks, axis=1)
                tails = [out_delim.join(v) for v in appended]
                out.writelines(
                    f"{line.rstrip(chr(13) + chr(10))}{out_delim}{tail}\n"
                    for line, tail in zip(chunk, tails, strict=True)
                )
                row_number += len(chunk)
    return used


def _columns_for_apply(
    path: str,
    header: list[str],
    sensors: list[str],
    accel_cols: str | Sequence[str] | None,
    mag_cols: str | Sequence[str] | None,
) -> dict[str, list[str]]:
    guessed = recognise_columns(header)
    explicit = {"accel": _explicit(accel_cols), "mag": _explicit(mag_cols)}
    used: dict[str, list[str]] = {}
    for sensor in sensors:
        cols = explicit[sensor] or guessed.get(sensor)
        if cols is None:
            continue
        missing = [c for c in cols if c not in header]
        if missing:
            raise InputError(
                f"{path}: no column {missing[0]!r}; columns found: {', '.join(header)}"
            )
        used[sensor] = cols
    if not used:
        raise InputError(
            f"{path}: no columns for the calibrated sensors ({', '.join(sensors)}) among "
            f"{', '.join(header)}; pass --accel-cols/--mag-cols"
        )
    return used


def _apply_table(
    cal: Any,
    table: Table,
    dst: Path,
    sensors: list[str],
    accel_cols: str | Sequence[str] | None,
    mag_cols: str | Sequence[str] | None,
) -> dict[str, list[str]]:
    used = _columns_for_apply(table.path, table.names, sensors, accel_cols, mag_cols)
    out = {name: table.columns[name] for name in table.names}
    for sensor, cols in used.items():
        raw = np.column_stack([table.numeric(c) for c in cols])
        fixed = cal.correct_accel(raw) if sensor == "accel" else cal.correct_mag(raw)
        for c, column in zip(cols, fixed.T, strict=True):
            out[f"{c}_cal"] = column
    names = list(out)
    text = np.column_stack(
        [_format(v) if v.dtype.kind == "f" else v.astype(str) for v in out.values()]
    )
    with dst.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(names)
        writer.writerows(text.tolist())
    return used
