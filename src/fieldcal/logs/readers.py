"""Reading log tables: CSV (with a header), NPZ and Parquet, chosen by suffix.

:data:`READERS` maps a file suffix to its reader; anything else is read as delimited text. Each
reader returns a :class:`Table` of numeric (float) and text columns; every problem is an
:class:`~fieldcal.errors.InputError` naming the row, the column and the fix. pyarrow (Parquet)
loads only when a Parquet file is read.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError

__all__ = ["READERS", "Table", "read_table", "to_float"]

Array = NDArray[np.float64]


@dataclass
class Table:
    """Columns of a log as read: numeric columns as float arrays, others as string arrays."""

    path: str
    names: list[str]
    columns: dict[str, NDArray[np.generic]]

    @property
    def n_rows(self) -> int:
        return 0 if not self.names else len(self.columns[self.names[0]])

    def numeric(self, name: str) -> Array:
        """Column ``name`` as floats; a one-line error naming the first non-numeric value."""
        values = self.columns[name]
        if values.dtype.kind == "f":  # float32 from .npz or .parquet too
            return values.astype(np.float64, copy=False)
        if values.dtype.kind in "iub":
            return values.astype(float)
        return to_float(values, name, self.path)


def to_float(values: NDArray[np.generic], name: str, path: str, first_row: int = 0) -> Array:
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
    columns: dict[str, NDArray[np.generic]] = {}
    for j, name in enumerate(header):
        column = np.char.strip(cells[:, j])
        filled = np.where(column == "", "nan", column)
        try:
            columns[name] = filled.astype(float)
        except ValueError:
            columns[name] = column  # text (labels, device names); checked when used
    return Table(str(path), header, columns)


def _read_npz(path: Path) -> Table:
    columns: dict[str, NDArray[np.generic]] = {}
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


#: suffix -> reader; any other suffix is read as delimited text (CSV, TSV, blank-separated).
READERS: dict[str, Callable[[Path], Table]] = {
    ".npz": _read_npz,
    ".parquet": _read_parquet,
    ".pq": _read_parquet,
}


def read_table(path: str | Path) -> Table:
    """Read a CSV (header line, ``,`` ``;`` tab or blank separated), ``.npz`` or ``.parquet``."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file; check the path")
    if path.is_dir():
        raise InputError(f"{path}: is a folder; give the log file inside it")
    reader = READERS.get(path.suffix.lower(), _read_csv)
    try:
        return reader(path)
    except InputError:
        raise
    except (OSError, ValueError) as exc:
        raise InputError(
            f"{path}: cannot read it ({exc}); give a readable CSV, .npz or .parquet"
        ) from None
