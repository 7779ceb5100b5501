"""Reading log tables: CSV (with a header), NPZ and Parquet, chosen by suffix.

:data:`READERS` maps a file suffix to its reader; anything else is read as delimited text. Each
reader returns a :class:`Table` of numeric (float) and text columns; every problem is an
:class:`~fieldcal.errors.InputError` naming the row, the column and the fix. Only regular files
are read: a pipe, a device or a folder is refused before it is opened (a FIFO would block, a
device never end). pyarrow (Parquet) loads only when a Parquet file is read.
"""

from __future__ import annotations

import csv
import os
import stat
import zipfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError

__all__ = ["READERS", "Table", "read_table", "regular_file", "to_float"]

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
        kind = values.dtype.kind
        if kind == "f":  # float16/32 from .npz or .parquet too
            return values.astype(np.float64, copy=False)
        if kind in "iu":
            return values.astype(float)
        what = _NOT_READINGS.get(kind)
        if what is not None:
            raise InputError(
                f"{self.path}: column {name!r} holds {what}, not numbers; give readings as "
                "real numbers (or choose other columns)"
            )
        return to_float(values, name, self.path)


#: dtype kinds that are not readings, and what to call them.
_NOT_READINGS = {
    "b": "true/false values",
    "c": "complex numbers (take the real part if the imaginary parts are zero)",
    "M": "dates and times",
    "m": "time spans",
    "V": "records",
}


def to_float(values: NDArray[np.generic], name: str, path: str, first_row: int = 0) -> Array:
    try:
        text = np.char.strip(values.astype(str))
    except UnicodeDecodeError:
        raise InputError(
            f"{path}: column {name!r} holds bytes that are not text; give readings as numbers"
        ) from None
    text = np.where(text == "", "nan", text)  # an empty field is a missing value, not text
    try:
        return text.astype(float)
    except ValueError:
        bad = next(i for i, v in enumerate(text) if not _is_number(v))
        raise InputError(
            f"{path}: column {name!r} has a non-numeric value {_short(str(text[bad]))} at data "
            f"row {first_row + bad + 1}; fix or remove that row (or choose other columns)"
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


def _split(
    lines: Sequence[str], delimiter: str | None, path: str = "", first_row: int = 0
) -> list[list[str]]:
    """Fields of each line; a line the csv module cannot split (a field over its limit of
    131,072 characters) is an :class:`InputError` naming the row. ``first_row`` is the data-row
    number of ``lines[0]`` (0: it is the header line)."""
    if delimiter is None:
        return [line.split() for line in lines]
    reader = csv.reader(lines, delimiter=delimiter)
    try:
        return list(reader)
    except csv.Error as exc:
        where = f"{path}: " if path else ""
        row = first_row + reader.line_num - 1
        line = f"data row {row}" if row > 0 else "the header line"
        raise InputError(
            f"{where}cannot split {line} into fields ({exc}); a sensor log has short numeric "
            "fields: fix that line (an unmatched quote?) or cut it"
        ) from None


def _short(text: str, limit: int = 60) -> str:
    return repr(text if len(text) <= limit else text[:limit] + "...")


def _names(names: Sequence[str], limit: int = 12) -> str:
    """Column names for a message, the list cut after ``limit``."""
    shown = ", ".join(_short(n, 30)[1:-1] for n in names[:limit])
    return shown + (f" ... ({len(names)} columns)" if len(names) > limit else "")


#: Longest field of a CSV log: readings and labels are short, and numpy's text arrays would
#: make every cell as wide as the widest one.
LONGEST_FIELD = 1000


def _check_lengths(path: Path, lines: Sequence[str], rows: Sequence[Sequence[str]]) -> None:
    """Refuse a field longer than :data:`LONGEST_FIELD` characters, naming its row."""
    for i, line in enumerate(lines):
        if len(line) > LONGEST_FIELD:
            long = [len(f) for f in rows[i] if len(f) > LONGEST_FIELD]
            if long:
                where = f"data row {i}" if i else "the header line"
                raise InputError(
                    f"{path}: {where} has a field of {long[0]:,} characters; a sensor log has "
                    "short fields: fix that line (an unmatched quote?) or cut it"
                )


def _check_header(path: Path, header: list[str]) -> None:
    seen: dict[str, int] = {}
    for j, name in enumerate(header):
        if name in seen:
            label = f"column name {_short(name)}" if name else "an empty column name"
            raise InputError(
                f"{path}: {label} appears twice (columns {seen[name] + 1} and {j + 1}); give "
                "every column its own name"
            )
        seen[name] = j


def _ragged(path: Path, header: list[str], widths: NDArray[np.int64], first: str) -> InputError:
    ragged = np.flatnonzero(widths != len(header))
    i = int(ragged[0])
    common = int(np.bincount(widths).argmax())
    if ragged.size > widths.size // 2 and common != len(header):
        # most rows disagree with the first line: it is not the header (a logger's preamble)
        return InputError(
            f"{path}: the header line {_short(first)} has {len(header)} field(s) but the data "
            f"rows have {common}; delete the lines above the header (or start them with #)"
        )
    return InputError(
        f"{path}: data row {i + 1} has {widths[i]} fields but the header has {len(header)}; "
        f"fix the row ({ragged.size} such row(s)) or cut the file"
    )


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
    below = {_sniff_delimiter(line) for line in lines[1:6]}
    if delimiter is None and len(below) == 1 and None not in below:
        # a logger's preamble above the header ("Logger v2", "Date: ...")
        raise InputError(
            f"{path}: the first line {_short(lines[0].strip())} is not a header (the lines below "
            f"are separated by {below.pop()!r}); delete the lines above the header (or start "
            "them with #)"
        )
    rows = _split(lines, delimiter, str(path))
    if len(rows) == len(lines):  # (a quoted field across lines would shift the numbering)
        _check_lengths(path, lines, rows)
    elif any(len(f) > LONGEST_FIELD for r in rows for f in r):
        raise InputError(
            f"{path}: a field is longer than {LONGEST_FIELD:,} characters (an unmatched quote "
            "joins lines); fix the quoting or cut the file"
        )
    header = [h.strip() for h in rows[0]]
    if all(_is_number(h) for h in header):
        raise InputError(
            f"{path}: the first line is numbers, not a header; add a header line naming the "
            "columns, e.g. 't,ax,ay,az,mx,my,mz'"
        )
    _check_header(path, header)
    body = rows[1:]
    if not body:
        raise InputError(f"{path}: the file has a header but no data rows")
    widths = np.fromiter((len(r) for r in body), dtype=np.int64, count=len(body))
    if np.any(widths != len(header)):
        raise _ragged(path, header, widths, lines[0].strip())
    columns: dict[str, NDArray[np.generic]] = {}
    # column by column: a text array is as wide as its longest cell, so one long cell widens
    # its own column only
    for name, cells in zip(header, zip(*body, strict=True), strict=True):
        try:
            columns[name] = np.array(cells, dtype=float)  # float() takes surrounding blanks
            continue
        except ValueError:
            pass
        column = np.char.strip(np.array(cells, dtype=str))
        filled = np.where(column == "", "nan", column)
        try:
            columns[name] = filled.astype(float)
        except ValueError:
            columns[name] = column  # text (labels, device names); checked when used
    return Table(str(path), header, columns)


_NPZ_FIX = "save the arrays with numpy.savez, e.g. accel=(n, 3), mag=(n, 3), t=(n,)"


def _read_npz(path: Path) -> Table:
    columns: dict[str, NDArray[np.generic]] = {}
    skipped: list[str] = []
    try:
        data = np.load(path, allow_pickle=False)
        if not isinstance(data, np.lib.npyio.NpzFile):  # a bare .npy array
            raise InputError(f"{path}: a single .npy array, not an .npz archive; {_NPZ_FIX}")
        with data:
            arrays = {key: np.asarray(data[key]) for key in data.files}
    except InputError:
        raise
    except (zipfile.BadZipFile, EOFError, ValueError, OSError, KeyError) as exc:
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise InputError(f"{path}: not a readable .npz archive ({reason}); {_NPZ_FIX}") from None
    for key, array in arrays.items():
        if array.ndim == 2 and array.shape[1] == 3:
            # an (n, 3) array named like a sensor becomes three columns "<name>_x" ...
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
    return Table(str(path), list(columns), columns)


def _read_parquet(path: Path) -> Table:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise InputError(
            f"{path}: reading Parquet needs pyarrow; pip install 'fieldcal[parquet]' or give a CSV"
        ) from None
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
    return Table(str(path), names, columns)


#: suffix -> reader; any other suffix is read as delimited text (CSV, TSV, blank-separated).
READERS: dict[str, Callable[[Path], Table]] = {
    ".npz": _read_npz,
    ".parquet": _read_parquet,
    ".pq": _read_parquet,
}


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


def read_table(path: str | Path) -> Table:
    """Read a CSV (header line, ``,`` ``;`` tab or blank separated), ``.npz`` or ``.parquet``."""
    path = regular_file(path)
    reader = READERS.get(path.suffix.lower(), _read_csv)
    try:
        return reader(path)
    except InputError:
        raise
    except (OSError, ValueError, EOFError, MemoryError) as exc:
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise InputError(
            f"{path}: cannot read it ({reason}); give a readable CSV, .npz or .parquet"
        ) from None
