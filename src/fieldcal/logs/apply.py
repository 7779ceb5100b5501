"""Apply a calibration to a log file: calibrated columns appended, everything else kept as it was.

:func:`apply_to_file` writes the output in the format its suffix names (``.csv`` or any other
text suffix, ``.parquet``/``.pq``, ``.npz``), atomically (:func:`fieldcal._files.replacing`):
an error or Ctrl-C half-way leaves the previous output untouched and no fragment.

- Text in, text out is streamed ``CHUNK_ROWS`` lines at a time, so files larger than memory
  work: every input line is copied byte for byte (comment and blank lines, a preamble above
  the header, the line endings, a byte-order mark) and the calibrated values follow each data
  line (and the names the header line, a ``#`` header included). Each chunk is vectorised: a
  chunk of :data:`ARROW_MIN_ROWS` data lines or more with nothing unusual is done by pyarrow
  alone (it reads the sensors' fields, formats the values as ``repr`` would and joins them to
  the lines, in bulk); otherwise numpy's C parser reads the fields, the calibration runs on
  all rows at once and the values are formatted in one pass (pyarrow or ``repr``); a chunk
  numpy would not read exactly as the csv module (quotes, mixed line endings, a bad value) is
  done line by line, which names the problem.
- Otherwise the table is read in its own types and written whole: Parquet keeps its schema
  (column types and metadata), NPZ each array as it was (dtype and shape; an ``(n, 3)`` sensor
  array gets an ``(n, 3)`` ``<name>_cal``), and columns written as text keep their full
  precision (the shortest text that reads back as the same value of their type).

Calibrated values are doubles; as text, the shortest text that reads back as the same double
(with a decimal comma in a log written with decimal commas). A calibration whose biases have
temperature terms (``cal.<sensor>.temperature``) is applied with each row's temperature, from
the log's temperature column (recognised by name, or ``temp_col``) or one given
``temperature``; without either it is refused (the bias at the reference temperature alone
would be a silent error).
pyarrow loads only when a Parquet file is read or written, or a large text log is formatted.
"""

from __future__ import annotations

import csv
import importlib.util
import stat
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._files import replacing, same_file
from ..errors import InputError
from .arrow_parser import pyarrow_module
from .calibrated_columns import (
    Drive,
    Thermal,
    as_text,
    check_new_columns,
    columns_for_apply,
    corrected,
    reported_columns,
)
from .readers import FLIGHT_READERS, Table, npz_table, read_table
from .rosbag import is_bag, read_bag
from .streamed_text import ARROW_MIN_ROWS, apply_text

if TYPE_CHECKING:
    from ..calibration import Calibration

__all__ = ["ARROW_MIN_ROWS", "CHUNK_ROWS", "apply_to_file", "check_pyarrow", "output_format"]

Array = NDArray[np.float64]

#: Lines per chunk when a text log is streamed: each chunk is parsed, calibrated and formatted
#: at once (a few tens of MB of text in flight).
CHUNK_ROWS = 100_000

_PARQUET = (".parquet", ".pq")
_NPZ = ".npz"
_INSTALL = "pip install 'fieldcal[parquet]'"


def output_format(path: str | Path) -> str:
    """The format a path's suffix names: ``"parquet"``, ``"npz"`` or ``"text"`` (any other).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    str
    """
    suffix = Path(path).suffix.lower()
    if suffix in _PARQUET:
        return "parquet"
    return "npz" if suffix == _NPZ else "text"


def check_pyarrow(*paths: str | Path) -> None:
    """A one-line error when one of ``paths`` is Parquet and pyarrow is not installed.

    Parameters
    ----------
    *paths : str or Path

    Raises
    ------
    InputError
        Naming ``pip install 'fieldcal[parquet]'``.
    """
    for path in paths:
        if output_format(path) == "parquet" and importlib.util.find_spec("pyarrow") is None:
            raise InputError(
                f"{path}: Parquet needs pyarrow, which is not installed; {_INSTALL} (or use "
                ".csv or .npz)"
            )


def _parquet() -> tuple[ModuleType, ModuleType]:
    """pyarrow and pyarrow.parquet (:func:`check_pyarrow` has checked they are installed)."""
    pa, pq = pyarrow_module(), pyarrow_module("pyarrow.parquet")
    if pa is None or pq is None:
        raise InputError(f"Parquet needs pyarrow, which is not installed; {_INSTALL}")
    return pa, pq


def apply_to_file(
    cal: Calibration,
    src: str | Path,
    dst: str | Path,
    *,
    accel_cols: str | Sequence[str] | None = None,
    mag_cols: str | Sequence[str] | None = None,
    chunk_rows: int | None = None,
    on_progress: Callable[[str], None] | None = None,
    decimal: str | None = None,
    imu_topic: str | None = None,
    mag_topic: str | None = None,
    temp_col: str | None = None,
    temperature: float | None = None,
    current_col: str | None = None,
    throttle_col: str | None = None,
    gyro_cols: str | Sequence[str] | None = None,
    mag_instance: int | None = None,
    imu_instance: int | None = None,
) -> dict[str, list[str]]:
    """Append calibrated columns (``<col>_cal``) to a log and write it to ``dst``: the
    accelerometer's, the magnetometer's and the gyroscope's (rad/s) that the calibration
    holds and the log has.

    Parameters
    ----------
    cal : Calibration
    src : str or Path
        The log: CSV (any other suffix is delimited text), ``.npz`` or ``.parquet``.
    dst : str or Path
        The output, in the format its suffix names (see the module docstring); replaced
        atomically if it exists. It must not be ``src`` (compared by file identity).
    accel_cols, mag_cols, gyro_cols : str or sequence of str, optional
        The sensors' columns (default: recognised by name); a sensor the calibration holds
        whose columns the log lacks is left out (not all of them).
    chunk_rows : int, optional
        Lines per chunk when text is streamed (default :data:`CHUNK_ROWS`).
    on_progress : callable, optional
        Told the rows done about once a second while text is streamed (one line of text).
    decimal : {None, ".", ","}
        Text logs: the decimal mark (None recognises decimal commas as
        :func:`~fieldcal.logs.readers.read_table` does); calibrated values are written with
        the log's own mark.
    imu_topic, mag_topic : str, optional
        A ROS bag's topics (:func:`~fieldcal.logs.rosbag.read_bag`): its table (``t``,
        ``ax``.., ``gx``.., ``mx``..) is written with the calibrated columns.
    temp_col : str, optional
        The temperature column (°C), for a calibration with temperature terms (default: the
        column the calibration recorded, ``options["columns"]["temperature"]``, when the log
        has it; else recognised by name, as ``calibrate`` does).
    temperature : float, optional
        One temperature (°C) for every row, instead of a column.
    current_col, throttle_col : str, optional
        For a calibration with an interference term (:mod:`fieldcal.interference`): the
        battery-current or throttle column (default: recognised by name); the log is then
        read whole (a CSV is written again, not streamed line by line).
    mag_instance, imu_instance : int, optional
        A flight log's (``.ulg``, ``.bin``) magnetometer and IMU instances (default: the
        primary ones), as the calibration read them (:func:`~fieldcal.logs.readers.read_table`).

    Returns
    -------
    dict of str -> list of str
        The columns used per sensor (and ``"temperature"``: the temperature column, when the
        calibration's terms were applied with one).

    Raises
    ------
    InputError
        A missing or unreadable log, no columns for the calibrated sensors, a non-numeric
        value (column, value and data row), a log that already has the ``_cal`` columns,
        ``dst`` the log itself, or Parquet without pyarrow.
    """
    src, dst = Path(src), Path(dst)
    if same_file(src, dst):
        raise InputError(f"{dst}: is the input log {src}; write the output to another file")
    check_pyarrow(src, dst)
    sensors = [s for s in ("accel", "mag", "gyro") if getattr(cal, s, None) is not None]
    columns = {"accel": accel_cols, "mag": mag_cols, "gyro": gyro_cols}
    thermal = Thermal(cal, sensors, temp_col, temperature)
    drive = Drive(cal, current_col, throttle_col)
    reading = _Reading(decimal, mag_instance, imu_instance)
    if is_bag(src):  # (a rosbag2 bag is a folder)
        bag = read_bag(src, imu_topic=imu_topic, mag_topic=mag_topic, on_progress=on_progress)
        return _apply_table(cal, src, dst, sensors, columns, table=bag, thermal=thermal)
    if drive.model is not None or src.suffix.lower() in FLIGHT_READERS:
        # the interference term needs each row's current: the table path reads the whole log
        return _apply_table(cal, src, dst, sensors, columns, reading, thermal=thermal, drive=drive)
    _check_source(src, decimal)
    if output_format(src) == output_format(dst) == "text":
        rows = chunk_rows or CHUNK_ROWS
        return apply_text(cal, src, dst, sensors, columns, rows, on_progress, decimal, thermal)
    return _apply_table(cal, src, dst, sensors, columns, reading, thermal=thermal)


def _check_source(src: Path, decimal: str | None) -> None:
    """A log file that can be read (not missing, a folder, a pipe or a device) and a decimal
    mark apply knows, else a one-line error."""
    try:
        mode = src.stat().st_mode
    except FileNotFoundError:
        raise InputError(f"{src}: no such file; check the path") from None
    if stat.S_ISDIR(mode):
        raise InputError(f"{src}: is a folder; give the log file inside it")
    if not stat.S_ISREG(mode):  # a pipe would block, a device never end
        raise InputError(f"{src}: is not a regular file; save the log to a file and give that")
    if decimal not in (None, ".", ","):
        raise InputError(f"decimal must be '.' or ',' (or None to recognise it); got {decimal!r}")


# ----------------------------------------------------------------------------- tables
def _read_npz(src: Path) -> tuple[dict[str, NDArray[np.generic]], bool]:
    """Every array of an ``.npz`` as stored, and whether the archive was compressed."""
    try:
        with zipfile.ZipFile(src) as archive:
            compressed = any(i.compress_type != zipfile.ZIP_STORED for i in archive.infolist())
        with np.load(src, allow_pickle=False) as data:
            arrays = {key: np.asarray(data[key]) for key in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(f"{src}: cannot read it as .npz ({exc}); give a readable file") from None
    return arrays, compressed


def _parquet_columns(src: Path, table: Any) -> Table:
    columns: dict[str, NDArray[np.generic]] = {}
    for name in table.schema.names:
        values = np.asarray(table.column(name).to_numpy(zero_copy_only=False))
        if values.dtype.kind == "O":
            values = np.array(["" if v is None else str(v) for v in values.tolist()], dtype=str)
        columns[name] = values
    return Table(str(src), list(columns), columns)


class _Reading(NamedTuple):
    """How a log read whole is read: a text log's decimal mark, a flight log's magnetometer
    and IMU instances (:func:`~fieldcal.logs.readers.read_table`'s keywords)."""

    decimal: str | None = None
    mag_instance: int | None = None
    imu_instance: int | None = None


def _apply_table(
    cal: Calibration,
    src: Path,
    dst: Path,
    sensors: list[str],
    columns: dict[str, str | Sequence[str] | None],
    reading: _Reading | None = None,
    *,
    table: Table | None = None,
    thermal: Thermal,
    drive: Drive | None = None,
) -> dict[str, list[str]]:
    """The calibrated columns through a table read whole (``table``: one already read);
    ``drive`` takes the magnetometer's interference term off with each row's current."""
    fmt_in, fmt_out = output_format(src), output_format(dst)
    arrays: dict[str, NDArray[np.generic]] = {}
    compressed = False
    arrow: Any = None
    if table is not None:
        fmt_in = "table"
    elif fmt_in == "npz":
        arrays, compressed = _read_npz(src)
        table = npz_table(src, arrays)
    elif fmt_in == "parquet":
        pa, pq = _parquet()
        try:
            arrow = pq.read_table(src)
        except Exception as exc:  # pyarrow's errors are many classes; all mean the same here
            raise InputError(
                f"{src}: cannot read it as Parquet ({' '.join(str(exc).split())}); give a "
                "readable file"
            ) from None
        table = _parquet_columns(src, arrow)
    else:
        table = read_table(src, **(reading or _Reading())._asdict())
    used = columns_for_apply(table.path, table.names, sensors, columns)
    temp_name = thermal.find(table.path, table.names)
    t = thermal.values(None if temp_name is None else table.numeric(temp_name), temp_name)
    shift = None if drive is None else drive.shift(table)
    fixed = {
        sensor: corrected(
            cal,
            sensor,
            np.column_stack([table.numeric(c) for c in cols])
            - (shift if sensor == "mag" and shift is not None else 0.0),
            t,
        )
        for sensor, cols in used.items()
    }
    reported = reported_columns(used, temp_name)
    new: dict[str, Array] = {
        f"{c}_cal": column
        for sensor, cols in used.items()
        for c, column in zip(cols, fixed[sensor].T, strict=True)
    }
    check_new_columns(table.path, table.names, list(new))

    if fmt_out == "npz":
        if fmt_in == "npz":
            out = dict(arrays)
            for sensor, cols in used.items():
                key = _sensor_array(arrays, cols)
                if key is not None:  # an (n, 3) sensor array gets an (n, 3) calibrated one
                    check_new_columns(table.path, list(arrays), [f"{key}_cal"])
                    out[f"{key}_cal"] = fixed[sensor]
                else:
                    out.update({f"{c}_cal": new[f"{c}_cal"] for c in cols})
        else:
            out = {**table.columns, **new}
        with replacing(dst) as temp:
            _write_npz(temp, out, compressed)
        return reported
    if fmt_in == "npz":
        _only_columns(src, arrays)
    if fmt_out == "parquet":
        pa, pq = _parquet()
        if arrow is None:
            arrow = pa.table({name: table.columns[name] for name in table.names})
        for name, column in new.items():
            arrow = arrow.append_column(name, pa.array(column, type=pa.float64()))
        with replacing(dst) as temp:
            pq.write_table(arrow, str(temp))
        return reported
    delimiter = "\t" if dst.suffix.lower() == ".tsv" else ","
    names = [*table.names, *new]
    texts = [as_text(table.columns[name]) for name in table.names] + [
        as_text(v) for v in new.values()
    ]
    with replacing(dst) as temp, temp.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, delimiter=delimiter, lineterminator="\n")
        writer.writerow(names)
        writer.writerows(zip(*texts, strict=True))
    return reported


def _sensor_array(arrays: dict[str, NDArray[np.generic]], cols: list[str]) -> str | None:
    """The ``(n, 3)`` array ``cols`` were split from (``accel`` for ``accel_x..z``), if any."""
    key = cols[0][:-2]
    whole = arrays.get(key)
    if whole is None or whole.ndim != 2 or whole.shape[1] != 3:
        return None
    return key if cols == [f"{key}_{axis}" for axis in "xyz"] else None


def _only_columns(src: Path, arrays: dict[str, NDArray[np.generic]]) -> None:
    """Refuse arrays a table cannot hold (rather than leaving them out of the output)."""
    for key, array in arrays.items():
        if not (array.ndim == 1 or (array.ndim == 2 and array.shape[1] == 3)):
            raise InputError(
                f"{src}: the array {key!r} (shape {array.shape}) is not a column; write the "
                "output as .npz to keep it"
            )


def _write_npz(path: Path, arrays: dict[str, NDArray[np.generic]], compressed: bool) -> None:
    """``np.savez`` by hand: any key (``np.savez`` reserves ``file``), no pickles."""
    mode = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
    with zipfile.ZipFile(path, "w", compression=mode, allowZip64=True) as archive:
        for key, array in arrays.items():
            with archive.open(f"{key}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(array), allow_pickle=False)
