"""Reading log tables: delimited text (with a header), NPZ and Parquet, chosen by suffix.

:data:`READERS` maps a file suffix to its reader; anything else is read as delimited text
(:mod:`fieldcal.logs.text`: CSV, TSV or blank separated, a preamble or a ``#`` header, decimal
commas; a fast path with pyarrow's or numpy's C parser, the careful reader where it gives
up). Each reader returns a :class:`Table` of numeric (float) and text columns; every problem is
an :class:`~fieldcal.errors.InputError` naming the row, the column and the fix. Only regular
files are read: a pipe, a device or a folder is refused before it is opened (a FIFO would
block, a device never end). pyarrow loads only when a Parquet file or a large text log is read
(:func:`~fieldcal.logs.text.pyarrow_module`).
"""

from __future__ import annotations

import os
import stat
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .arrow_parser import pyarrow_module
from .dataflash import read_dataflash
from .flight import FlightLog, flight_table
from .raw_table import Table, to_float
from .sniff import not_a_log
from .text import LONGEST_FIELD, _check_header, read_text
from .text_layout import metadata_key
from .ulog import read_ulog

__all__ = [
    "FLIGHT_READERS",
    "LONGEST_FIELD",
    "READERS",
    "Table",
    "instance_number",
    "npz_table",
    "read_table",
    "regular_file",
    "to_float",
]

Array = NDArray[np.float64]


_NPZ_FIX = "save the arrays with numpy.savez, e.g. accel=(n, 3), mag=(n, 3), t=(n,)"


def _read_npz(path: Path) -> Table:
    try:
        # opened here, so that a damaged archive (np.load gives its file to the zip reader,
        # which fails) does not leave the file open
        with path.open("rb") as handle:
            data = np.load(handle, allow_pickle=False)
            if not isinstance(data, np.lib.npyio.NpzFile):  # a bare .npy array
                raise InputError(f"{path}: a single .npy array, not an .npz archive; {_NPZ_FIX}")
            with data:
                arrays = {key: np.asarray(data[key]) for key in data.files}
    except InputError:
        raise
    except (zipfile.BadZipFile, EOFError, ValueError, OSError, KeyError) as exc:
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise InputError(f"{path}: not a readable .npz archive ({reason}); {_NPZ_FIX}") from None
    return npz_table(path, arrays)


def npz_table(path: str | Path, arrays: dict[str, NDArray[np.generic]]) -> Table:
    """The table an ``.npz`` archive's arrays make: 1-D arrays are columns, an ``(n, 3)``
    array named like a sensor becomes three columns ``<name>_x`` ...; other shapes are left
    out (named in the error when nothing is left); every column as long as the others."""
    columns: dict[str, NDArray[np.generic]] = {}
    skipped: list[str] = []
    metadata: dict[str, str] = {}
    for key, array in arrays.items():
        if array.ndim == 0:  # np.savez(..., device="IMU-0042"): a scalar describes the log
            metadata.setdefault(metadata_key(key), str(array.item())[:200])
        elif array.ndim == 2 and array.shape[1] == 3:
            for axis, column in zip("xyz", array.T, strict=True):
                columns[f"{key}_{axis}"] = column
        elif array.ndim == 1:
            columns[key] = array
        else:
            skipped.append(f"{key} {list(array.shape)}")
    if not columns:
        found = f" (found {', '.join(skipped[:5])})" if skipped else ""
        raise InputError(f"{path}: no 1-D columns or (n, 3) arrays in the .npz{found}; {_NPZ_FIX}")
    lengths: dict[int, str] = {}
    for name, values in columns.items():
        lengths.setdefault(len(values), name)
    if len(lengths) > 1:
        shown = ", ".join(f"{name} {n}" for n, name in sorted(lengths.items())[:4])
        raise InputError(
            f"{path}: arrays of different lengths ({shown} rows); save one row per sample in "
            "every array"
        )
    return Table(str(path), list(columns), columns, metadata=metadata)


def _read_parquet(path: Path) -> Table:
    pa, pq = pyarrow_module(), pyarrow_module("pyarrow.parquet")
    if pa is None or pq is None:
        raise InputError(
            f"{path}: reading Parquet needs pyarrow; pip install 'fieldcal[parquet]' or give a CSV"
        )
    try:
        table = pq.read_table(path)
        names = list(table.schema.names)
        _check_header(path, names)
        columns = {
            name: table.column(j).to_numpy(zero_copy_only=False) for j, name in enumerate(names)
        }
    except InputError:
        raise
    except (pa.ArrowException, OSError, ValueError, TypeError) as exc:
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise InputError(
            f"{path}: not a readable Parquet file ({reason}); write it again or give a CSV"
        ) from None
    for name, values in columns.items():
        if values.dtype.kind == "O":  # text, or lists and nulls: kept as their text
            columns[name] = np.array([str(v) for v in values], dtype=str)
    return Table(str(path), names, columns, metadata=_parquet_metadata(table.schema.metadata))


def _parquet_metadata(raw: dict[bytes, bytes] | None) -> dict[str, str]:
    """A Parquet file's key-value metadata as text; the schemas pandas and Arrow store there
    are not about the log."""
    out: dict[str, str] = {}
    for key, value in (raw or {}).items():
        name = key.decode("utf-8", "replace")
        if name in ("pandas", "ARROW:schema"):
            continue
        out.setdefault(metadata_key(name), value.decode("utf-8", "replace").strip()[:200])
    return out


#: suffix -> reader; any other suffix is read as delimited text (CSV, TSV, blank-separated).
READERS: dict[str, Callable[[Path], Table]] = {
    ".npz": _read_npz,
    ".parquet": _read_parquet,
    ".pq": _read_parquet,
}


#: suffix -> flight-log reader (PX4 ULog through pyulog, ArduPilot DataFlash through
#: pymavlink; each optional extra imported when such a file is read): :mod:`.flight`.
FLIGHT_READERS: dict[str, Callable[[Path], FlightLog]] = {
    ".ulg": read_ulog,
    ".bin": read_dataflash,
}


def instance_number(value: object, flag: str) -> int | None:
    """A sensor instance (``--mag N``, ``--imu N``) as an int; a one-line error otherwise."""
    if value is None:
        return None
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        number = float("nan")
    if not (number.is_integer() and 0 <= number <= 255):
        raise InputError(f"{flag} {value!r}: give an instance number 0, 1, 2 ...")
    return int(number)


def regular_file(path: str | Path) -> Path:
    """``path`` if it is a regular file (following links); an :class:`InputError` otherwise.

    Checked with ``os.stat`` before anything opens the file: opening a FIFO blocks until a
    writer comes, and a device such as ``/dev/zero`` never ends.
    """
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise InputError(f"{path}: no such file; check the path") from None
    except OSError as exc:
        raise InputError(
            f"{path}: cannot read it ({exc.strerror or exc}); check the path"
        ) from None
    if stat.S_ISDIR(mode):
        raise InputError(f"{path}: is a folder; give the log file inside it")
    if not stat.S_ISREG(mode):
        kind = "a pipe (FIFO)" if stat.S_ISFIFO(mode) else "a device or socket"
        raise InputError(
            f"{path}: is {kind}, not a file; save the log to a file and give that file"
        )
    return path


def read_table(
    path: str | Path,
    *,
    decimal: str | None = None,
    on_progress: Callable[[str], None] | None = None,
    mag_instance: int | None = None,
    imu_instance: int | None = None,
) -> Table:
    """Read a log: delimited text (any suffix but those in :data:`READERS`), ``.npz``,
    ``.parquet``, or a flight log (:data:`FLIGHT_READERS`: ``.ulg``, ``.bin``).

    Parameters
    ----------
    path : str or Path
    decimal : {None, ".", ","}
        Text logs only: the decimal mark. None reads points, and decimal commas when the
        columns are separated by ``;`` or tabs and the numbers are written ``0,123`` (never
        ``0.123``); ``","`` reads commas in ``;``, tab or blank separated columns.
    on_progress : callable, optional
        Text logs only: told ``"reading <name>: <rows> rows"`` about every million rows and at
        the end.
    mag_instance, imu_instance : int, optional
        Flight logs only: the magnetometer and IMU instances (``--mag N``, ``--imu N``).

    Returns
    -------
    Table
        ``notes`` says what was done that the user may want to know (preamble lines skipped,
        the header taken from a ``#`` line, decimal commas read as points).

    Raises
    ------
    InputError
        One line: the file, the row and column where it applies, what was found, the fix.
    """
    path = regular_file(path)
    mag = instance_number(mag_instance, "--mag")
    imu = instance_number(imu_instance, "--imu")
    flight = FLIGHT_READERS.get(path.suffix.lower())
    if flight is not None:
        return flight_table(flight(path), mag=mag, imu=imu)
    if mag is not None or imu is not None:
        raise InputError(
            f"{path}: --mag/--imu choose a flight log's sensor instance (.ulg, .bin); for this "
            "log name the columns with --mag-cols/--accel-cols"
        )
    reader = READERS.get(path.suffix.lower())
    try:
        if reader is None:
            return read_text(path, decimal=decimal, on_progress=on_progress)
        return reader(path)
    except InputError:
        # a refused text log is most often another file given by mistake: say which
        if reader is None and (what := not_a_log(path)) is not None:
            raise InputError(what) from None
        raise
    except (OSError, ValueError, EOFError, MemoryError) as exc:
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise InputError(
            f"{path}: cannot read it ({reason}); give a readable CSV, .npz or .parquet"
        ) from None
