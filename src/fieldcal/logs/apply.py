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
import functools
import importlib.util
import io
import itertools
import re
import stat
import time
import zipfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np
from numpy.typing import NDArray

from .._files import replacing, same_file
from ..errors import InputError
from ..interference import InterferenceModel
from .arrow_parser import float_column, pyarrow_module
from .columns import explicit_columns, recognise_columns
from .drive_inputs import drive_inputs
from .readers import FLIGHT_READERS, Table, npz_table, read_table, to_float
from .rosbag import is_bag, read_bag
from .text import HEAD_LINES, layout, parse_numbers
from .text_lines import _split

if TYPE_CHECKING:
    from ..calibration import Calibration

__all__ = ["ARROW_MIN_ROWS", "CHUNK_ROWS", "apply_to_file", "check_pyarrow", "output_format"]

Array = NDArray[np.float64]

#: Lines per chunk when a text log is streamed: each chunk is parsed, calibrated and formatted
#: at once (a few tens of MB of text in flight).
CHUNK_ROWS = 100_000
#: Seconds between two progress reports.
PROGRESS_SECONDS = 1.0
#: Chunks of at least this many data rows have their calibrated values formatted by pyarrow
#: (where it is installed; its import, about 0.1 s, would cost more on a small log).
ARROW_MIN_ROWS = 20_000

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
    thermal = _Thermal(cal, sensors, temp_col, temperature)
    drive = _Drive(cal, current_col, throttle_col)
    if is_bag(src):  # (a rosbag2 bag is a folder)
        bag = read_bag(src, imu_topic=imu_topic, mag_topic=mag_topic, on_progress=on_progress)
        return _apply_table(cal, src, dst, sensors, columns, table=bag, thermal=thermal)
    if drive.model is not None or src.suffix.lower() in FLIGHT_READERS:
        # the interference term needs each row's current: the table path reads the whole log
        return _apply_table(cal, src, dst, sensors, columns, decimal, thermal=thermal, drive=drive)
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
    if output_format(src) == output_format(dst) == "text":
        try:
            return _apply_text(
                cal,
                src,
                dst,
                sensors,
                columns,
                chunk_rows or CHUNK_ROWS,
                on_progress,
                decimal,
                thermal,
            )
        except UnicodeDecodeError:
            raise InputError(f"{src}: not a text file; give a CSV with a header line") from None
        except csv.Error as exc:
            raise InputError(f"{src}: cannot read it as CSV ({exc}); fix the file") from None
    return _apply_table(cal, src, dst, sensors, columns, decimal, thermal=thermal)


@dataclass(frozen=True)
class _Drive:
    """A calibration's interference term as apply needs it (:mod:`fieldcal.interference`):
    the magnetometer's shift for each row's current or throttle, from the column recognised
    by name or named (``--current-col``, ``--throttle-col``)."""

    cal: Calibration
    current_col: str | None
    throttle_col: str | None

    @property
    def model(self) -> InterferenceModel | None:
        model = getattr(self.cal.mag, "interference", None)
        return model if model is not None and model.identifiable else None

    def shift(self, table: Table) -> Array | None:
        """The magnetometer's shift (n, 3) for the table's rows; None without a term."""
        model = self.model
        if model is None:
            return None
        rows = np.arange(table.n_rows)
        inputs, _ = drive_inputs(table, rows, self.current_col, self.throttle_col)
        wanted = model.inputs[0]
        if wanted not in inputs:
            flag = "--current-col" if wanted == "current" else "--throttle-col"
            raise InputError(
                f"{table.path}: the calibration's magnetometer has an interference term in "
                f"{wanted} but the log has no {wanted} column; name it with {flag}"
            )
        if "temperature" in model.inputs and "temp" in table.columns:
            inputs["temperature"] = table.numeric("temp")
        return model.shift(inputs)


@dataclass(frozen=True)
class _Thermal:
    """A calibration's temperature terms as apply needs them: which sensors have terms, the
    column asked for, or one temperature for every row."""

    cal: Calibration
    sensors: list[str]
    column: str | None
    constant: float | None

    def __post_init__(self) -> None:
        if self.column is not None and not isinstance(self.column, str):
            raise InputError(f"temp_col must be a column name, got {self.column!r}")
        if self.constant is not None and not (
            isinstance(self.constant, (int, float)) and np.isfinite(self.constant)
        ):
            raise InputError(f"temperature must be a number (deg C), got {self.constant!r}")

    @property
    def needed(self) -> list[str]:
        """The sensors whose biases have temperature terms."""
        out = []
        for s in self.sensors:
            model = getattr(self.cal, s).temperature
            if model is not None and model.order > 0:
                out.append(s)
        return out

    def find(self, path: str, header: list[str]) -> str | None:
        """The temperature column to read (None: none needed, or the constant given)."""
        needed = self.needed
        if not needed or self.constant is not None:
            return None
        found = recognise_columns(header).get("temperature")
        recorded = (self.cal.options.get("columns") or {}).get("temperature") or [None]
        if recorded[0] in header:  # the column the calibration was fitted with
            found = recorded
        name = self.column or (found[0] if found else None)
        if name is None:
            raise InputError(
                f"{path}: the calibration's {' and '.join(needed)} bias depends on temperature "
                "but the log has no temperature column; name it with --temp-col, or give one "
                "temperature for every row with --temperature"
            )
        if name not in header:
            raise InputError(f"{path}: no column {name!r}; columns found: {', '.join(header)}")
        return name

    def values(self, t: Array | None, name: str | None = None) -> Array | float | None:
        """The temperatures for a chunk of rows: the column's (checked), the constant, or
        None."""
        if t is None:
            return self.constant
        if not np.all(np.isfinite(t)):
            row = int(np.argmin(np.isfinite(t)))
            raise InputError(
                f"the temperature column {name!r} has a value that is not a finite number "
                f"({t[row]!r}, {row + 1}. row of a chunk); fix the log or give --temperature"
            )
        return t


def _reported(used: dict[str, list[str]], temp: str | None) -> dict[str, list[str]]:
    return used if temp is None else {**used, "temperature": [temp]}


# ----------------------------------------------------------------------------- shared
def _columns_for_apply(
    path: str,
    header: list[str],
    sensors: list[str],
    columns: dict[str, str | Sequence[str] | None],
) -> dict[str, list[str]]:
    guessed = recognise_columns(header)
    used: dict[str, list[str]] = {}
    for sensor in sensors:
        cols = explicit_columns(columns[sensor]) or guessed.get(sensor)
        if cols is None:
            continue
        missing = [c for c in cols if c not in header]
        if missing:
            raise InputError(f"{path}: no column {missing[0]!r}; columns found: {_shown(header)}")
        used[sensor] = cols
    if not used:
        raise InputError(
            f"{path}: no columns for the calibrated sensors ({', '.join(sensors)}) among "
            f"{_shown(header)}; pass --accel-cols/--mag-cols/--gyro-cols"
        )
    return used


#: A message shows at most this many characters of a file's header.
SHOWN = 80


def _shown(header: Sequence[str]) -> str:
    """The header's names for a message: control characters escaped, cut after
    :data:`SHOWN` characters (a file of NUL bytes is one 10,000-character name)."""
    text = ", ".join(header)
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text[: SHOWN * 4])
    if len(text) > SHOWN:
        return f"{text[:SHOWN]}... ({len(header)} column(s))"
    return text


def _check_new(path: str, existing: Sequence[str], new: Sequence[str]) -> None:
    clash = [name for name in new if name in existing]
    if clash:
        raise InputError(
            f"{path}: already has the column {clash[0]!r}: the log was calibrated before; "
            "apply the calibration to the raw log"
        )


def _correct(
    cal: Calibration, sensor: str, raw: Array, temperature: Array | float | None = None
) -> Array:
    if sensor == "accel":
        return cal.correct_accel(raw, temperature)
    if sensor == "gyro":
        return cal.correct_gyro(raw, temperature)
    return cal.correct_mag(raw, temperature)


def _text(values: NDArray[Any]) -> list[str]:
    """Each value as the shortest text that reads back as the same value of its type."""
    if values.dtype == np.float64:
        return list(map(repr, values.tolist()))  # Python's repr: shortest round trip
    if values.dtype.kind == "O":
        return ["" if v is None else str(v) for v in values.tolist()]
    return values.astype(str).tolist()  # numpy's shortest round trip for float32 too


# ----------------------------------------------------------------------------- text
def _is_data(line: str) -> bool:
    """Not blank and not a ``#`` comment (the readers' rule); a byte-order mark is ignored."""
    content = line.lstrip("\ufeff").strip()
    return bool(content) and not content.startswith("#")


def _ending(line: str) -> tuple[str, str]:
    body = line.rstrip("\r\n")
    return body, line[len(body) :]


#: Control characters that ``str.split()`` takes for blanks and numpy's parser does not.
_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")


@dataclass
class _Text:
    """What every chunk of a text log needs: where the sensors' fields are, how to write."""

    cal: Calibration
    src: Path
    delimiter: str | None
    decimal: str
    sep: str
    where: dict[str, list[int]]
    used: dict[str, list[str]]
    thermal: _Thermal
    temp_index: int | None = None
    temp_name: str | None = None


def _apply_text(
    cal: Calibration,
    src: Path,
    dst: Path,
    sensors: list[str],
    columns: dict[str, str | Sequence[str] | None],
    chunk_rows: int,
    on_progress: Callable[[str], None] | None,
    decimal: str | None,
    thermal: _Thermal,
) -> dict[str, list[str]]:
    size = max(src.stat().st_size, 1)
    with (
        src.open(newline="", encoding="utf-8") as handle,
        replacing(dst) as temp,
        temp.open("w", newline="", encoding="utf-8") as out,
    ):
        head: list[str] = []
        count = 0
        for line in handle:  # the lines the header is looked for in (the readers' rule)
            head.append(line)
            count += _is_data(line)
            if count == HEAD_LINES:
                break
        if count == 0:
            raise InputError(f"{src}: the file is empty; give a CSV with a header line")
        found = layout(src, [head[0].removeprefix("\ufeff"), *head[1:]], decimal)
        out.writelines(head[: found.header_index])  # preamble, comments, blank lines as they were
        body, ending = _ending(head[found.header_index])
        delimiter = found.delimiter
        header = [h.strip() for h in _split([found.header], delimiter)[0]]
        used = _columns_for_apply(str(src), header, sensors, columns)
        where = {s: [header.index(c) for c in cols] for s, cols in used.items()}
        new_names = [f"{c}_cal" for cols in used.values() for c in cols]
        _check_new(str(src), header, new_names)
        sep = delimiter or " "
        if delimiter is None:
            names = sep.join(new_names)
        else:  # quoted as the csv module quotes (a name holding the delimiter, a quote)
            buffer = io.StringIO()
            csv.writer(buffer, delimiter=delimiter, lineterminator="").writerow(new_names)
            names = buffer.getvalue()
        out.write(f"{body}{sep}{names}{ending or chr(10)}")

        temp_name = thermal.find(str(src), header)
        index = None if temp_name is None else header.index(temp_name)
        job = _Text(cal, src, delimiter, found.decimal, sep, where, used, thermal, index, temp_name)
        rows_done, last = 0, time.monotonic()
        chars = sum(len(line) for line in head[: found.start])
        for block in _blocks(handle, head[found.start :], chunk_rows):
            bulk = _arrow_block(job, block)
            if bulk is not None:  # written as bytes, the text layer flushed first
                out.flush()
                out.buffer.write(bulk[0])
                rows = bulk[1]
            else:
                text, rows = _chunk(job, _LINE.findall(block), rows_done)
                out.write(text)
            rows_done += rows
            chars += len(block)
            now = time.monotonic()
            if on_progress is not None and now - last >= PROGRESS_SECONDS:
                last = now
                on_progress(f"apply: {rows_done:,} rows ({min(100 * chars / size, 100):.0f} %)")
    return _reported(used, temp_name)


#: A line with its ending as the file reads it with ``newline=""`` (``\n``, ``\r\n``, ``\r``).
_LINE = re.compile(r"[^\r\n]*(?:\r\n|\r|\n)|[^\r\n]+$")


def _blocks(handle: TextIO, first: list[str], chunk_rows: int) -> Iterator[str]:
    """The text after the header in blocks of whole lines, about ``chunk_rows`` lines each
    (read by size: the first lines' mean length), the lines already read first."""
    size = max(chunk_rows * max(sum(map(len, first)) // max(len(first), 1), 1), 1)
    pending = "".join(first)
    while True:
        more = handle.read(max(size - len(pending), 1)) if len(pending) < size else ""
        text = pending + more
        pending = ""
        if not text:
            return
        if more and not text.endswith("\n"):
            text += handle.readline()  # the line cut by the size, whole
        yield text


def _arrow_block(job: _Text, block: str) -> tuple[bytes, int] | None:
    """The output of a block of lines as bytes, the lines parsed, their values formatted and
    the lines joined with them by pyarrow, and its number of rows; None unless every line is
    a data line of the header's fields of numbers pyarrow reads as numpy's parser does (no
    quote, comment, blank line, ``(``; one kind of line ending; a decimal point; at least
    :data:`ARROW_MIN_ROWS` lines; pyarrow installed): :func:`_chunk` does the rest."""
    if job.delimiter is None or job.decimal != "." or any(c in block for c in '"#('):
        return None
    n_lf, n_cr = block.count("\n"), block.count("\r")
    eol = "\n" if n_cr == 0 else "\r\n" if n_cr == block.count("\r\n") == n_lf else None
    if eol is None or n_lf + 1 < ARROW_MIN_ROWS or not block.isascii():
        return None
    pa, pc, pa_csv = pyarrow_module(), pyarrow_module("pyarrow.compute"), _csv_module()
    if pa is None or pc is None or pa_csv is None or not _formats_as_repr():
        return None
    ended = block.endswith(eol)
    raw = block.encode("ascii") + (b"" if ended else eol.encode("ascii"))
    idx = [i for cols in job.where.values() for i in cols]
    if job.temp_index is not None:  # the rows' temperatures, last
        idx.append(job.temp_index)
    numbers = _arrow_numbers(pa, pa_csv, raw, job, idx)
    if numbers is None:
        return None
    lines = _line_array(pa, pc, raw, len(eol))
    if lines is None or len(lines) != len(numbers):
        return None  # a blank line pyarrow skipped
    texts = _arrow_texts(pa, pc, _fixed(job, numbers))
    # (scalars from buffers: pyarrow's own would import pandas)
    empty, sep, ending = _strings(pa, ["", job.sep, eol])
    joined = pc.binary_join_element_wise(lines, *texts, sep)
    joined = pc.binary_join_element_wise(joined, empty, ending)  # the line ending after
    _, offsets, data = joined.buffers()
    end = int(np.frombuffer(offsets, dtype=np.int32, count=len(joined) + 1)[-1])
    out = memoryview(data)[: end if ended else end - len(eol)]
    return bytes(out), len(numbers)


def _csv_module() -> ModuleType | None:
    return pyarrow_module("pyarrow.csv")


def _arrow_numbers(pa: Any, pa_csv: Any, raw: bytes, job: _Text, idx: list[int]) -> Array | None:
    """The fields ``idx`` of every line of ``raw`` (rows x fields), empty fields NaN; None when
    pyarrow refuses a line (a field it does not read as a number, another count of fields)."""
    first = raw[: raw.index(b"\n")].decode("ascii").rstrip("\r")
    width = max(1 + max(idx), len(_split([first], job.delimiter)[0]))
    names = [f"f{i}" for i in range(width)]
    try:
        table = pa_csv.read_csv(
            pa.BufferReader(raw),
            read_options=pa_csv.ReadOptions(column_names=names),
            parse_options=pa_csv.ParseOptions(
                delimiter=job.delimiter, quote_char=False, double_quote=False,
                newlines_in_values=False, ignore_empty_lines=False,
            ),
            convert_options=pa_csv.ConvertOptions(
                include_columns=[names[i] for i in idx],
                column_types={names[i]: pa.float64() for i in idx},
                null_values=[""],
                strings_can_be_null=False,
            ),
        )  # fmt: skip
    except (pa.ArrowException, ValueError):
        return None
    out = np.empty((table.num_rows, len(idx)))
    for k, i in enumerate(idx):
        out[:, k] = float_column(table.column(names[i]))
    return out


def _line_array(pa: Any, pc: Any, raw: bytes, eol: int) -> Any:
    """The lines of ``raw`` (each ended) as a pyarrow string array without their endings."""
    ends = np.flatnonzero(np.frombuffer(raw, dtype=np.uint8) == 10) + 1
    if len(raw) >= 2**31:
        return None
    offsets = np.zeros(len(ends) + 1, dtype=np.int32)
    offsets[1:] = ends
    lines = pa.Array.from_buffers(
        pa.string(), len(ends), [None, pa.py_buffer(offsets), pa.py_buffer(raw)]
    )
    return pc.utf8_slice_codeunits(lines, 0, -eol)


def _fixed(job: _Text, numbers: Array) -> list[Array]:
    """The calibrated columns of the parsed fields (the sensors', then the temperature)."""
    fixed: list[Array] = []
    k = 0
    t = job.thermal.values(numbers[:, -1] if job.temp_index is not None else None, job.temp_name)
    for sensor, cols in job.where.items():
        fixed += list(_correct(job.cal, sensor, numbers[:, k : k + len(cols)], t).T)
        k += len(cols)
    return fixed


def _chunk(job: _Text, chunk: list[str], first_row: int) -> tuple[str, int]:
    """The output text of a chunk of lines and its number of data rows: every line as it was,
    the calibrated values after each data line. Vectorised; lines numpy does not parse exactly
    as the csv module and ``float`` do are done line by line (:func:`_tails`)."""
    joined = "".join(chunk)
    fast = _fast_chunk(job, joined)
    if fast is not None:
        return fast
    split = [(*_ending(line), _is_data(line)) for line in chunk]
    tails = iter(_tails(job, split, first_row))
    text = "".join(
        f"{body}{job.sep}{next(tails)}{ending}" if is_data else body + ending
        for body, ending, is_data in split
    )
    return text, sum(is_data for _, _, is_data in split)


def _fast_chunk(job: _Text, joined: str) -> tuple[str, int] | None:
    """:func:`_chunk` for lines with one kind of line ending, no quotes and numbers numpy's
    parser reads; None otherwise."""
    if '"' in joined or (
        job.delimiter is None and (not joined.isascii() or _CONTROL.search(joined))
    ):
        return None  # a quoted delimiter would shift the fields; str.split() knows more blanks
    if job.decimal == "," and "." in joined:
        return None  # a point in a decimal-comma log is named line by line
    n_cr = joined.count("\r")
    if n_cr == 0:
        eol = "\n"
    elif n_cr == joined.count("\r\n") == joined.count("\n"):
        eol = "\r\n"
    else:
        return None  # mixed line endings, or carriage returns alone
    pieces = joined.split(eol)
    ended = pieces[-1] == ""
    if ended:
        pieces.pop()
    everything = "#" not in joined and all(map(str.strip, pieces))
    mask = None if everything else [_is_data(p) for p in pieces]
    data = pieces if mask is None else list(itertools.compress(pieces, mask))
    if not data:
        return joined, 0
    idx = [i for cols in job.where.values() for i in cols]
    if job.temp_index is not None:  # the rows' temperatures, last
        idx.append(job.temp_index)
    numbers = parse_numbers(
        [line.replace(",", ".") for line in data] if job.decimal == "," else data,
        job.delimiter,
        idx,
    )
    if numbers is None or len(numbers) != len(data):
        return None
    fixed = _fixed(job, numbers)
    tails = _bulk_tails(fixed, job.sep, job.decimal) if len(data) >= ARROW_MIN_ROWS else None
    if tails is None:
        values = [column.tolist() for column in fixed]
        tail = (job.sep + "%r") * len(values)  # repr: the shortest text of the same double
        if mask is None and job.decimal == ".":  # one format per line, the line's text included
            text = eol.join(map(("%s" + tail).__mod__, zip(pieces, *values, strict=True)))
            return text + (eol if ended else ""), len(data)
        tails = list(map(tail.__mod__, zip(*values, strict=True)))
        if job.decimal == ",":
            tails = [t.replace(".", ",") for t in tails]
    if mask is None:
        text = eol.join(map(str.__add__, pieces, tails))
    else:
        it = iter(tails)
        text = eol.join(p + next(it) if m else p for p, m in zip(pieces, mask, strict=True))
    return text + (eol if ended else ""), len(data)


def _bulk_tails(columns: list[Array], sep: str, decimal: str) -> list[str] | None:
    """Each row's ``sep value sep value ...``, the values formatted as Python's ``repr`` writes
    them (the shortest text of the same double) but in bulk by pyarrow; None without it.

    pyarrow's shortest digits are Python's; its layout is too for a number written with a
    point and no exponent between 1e-4 and 1e16 (where ``repr`` writes no exponent). The rest
    (zeros and whole numbers, exponents, NaN, infinities) is written by ``repr``. Arrays and
    scalars are made from their buffers: ``pyarrow.array`` and ``pyarrow.scalar`` would import
    pandas, a second's work on a busy machine.
    """
    pa, pc = pyarrow_module(), pyarrow_module("pyarrow.compute")
    if pa is None or pc is None or not _formats_as_repr():
        return None
    return _arrow_tails(pa, pc, columns, sep, decimal)


#: Doubles on which pyarrow's layout is checked against ``repr`` before it is used.
_PROBES = (0.1, -2.5, 1 / 3, 123.456, 1e-4, 0.00012345678901234, 9.87654321e15, 6.02e15, 2 / 3e3)


@functools.cache
def _formats_as_repr() -> bool:
    """Whether this pyarrow writes doubles as ``repr`` does where :func:`_bulk_tails` takes
    its text (another version might not: then ``repr`` writes every value)."""
    pa, pc = pyarrow_module(), pyarrow_module("pyarrow.compute")
    probes = np.array(_PROBES)
    tails = _arrow_tails(pa, pc, [probes], ",", ".")
    return tails == ["," + repr(v) for v in _PROBES]


def _arrow_tails(pa: Any, pc: Any, columns: list[Array], sep: str, decimal: str) -> list[str]:
    # (an empty first piece: a leading separator)
    empty, separator = _strings(pa, ["", sep])
    joined = pc.binary_join_element_wise(empty, *_arrow_texts(pa, pc, columns), separator)
    if decimal == ",":
        joined = pc.replace_substring(joined, ".", ",")
    tails: list[str] = joined.to_pylist()
    return tails


def _arrow_texts(pa: Any, pc: Any, columns: list[Array]) -> list[Any]:
    """Each column's values as ``repr`` writes them, a pyarrow string array each."""
    texts = []
    for column in columns:
        column = np.ascontiguousarray(column, dtype=np.float64)
        n = len(column)
        text = pc.cast(pa.Array.from_buffers(pa.float64(), n, [None, pa.py_buffer(column)]),
                       pa.string())  # fmt: skip
        with np.errstate(invalid="ignore"):
            size = np.abs(column)
            far = (size < 1e-4) | ~(size < 1e16)  # (NaN too)
        bits = pa.py_buffer(np.packbits(far, bitorder="little"))
        odd = pa.Array.from_buffers(pa.bool_(), n, [None, bits])
        odd = pc.or_(odd, pc.invert(pc.match_substring(text, ".")))
        odd = pc.or_(odd, pc.match_substring(text, "e"))
        where = pc.indices_nonzero(odd).to_pylist()
        if where:
            again = _strings(pa, list(map(repr, column[where].tolist())))
            text = pc.replace_with_mask(text, odd, again)
        texts.append(text)
    return texts


def _strings(pa: ModuleType, texts: list[str]) -> Any:
    """A pyarrow string array of ASCII ``texts``, made from its buffers."""
    offsets = np.zeros(len(texts) + 1, dtype=np.int32)
    np.cumsum([len(t) for t in texts], out=offsets[1:])
    data = pa.py_buffer("".join(texts).encode("ascii"))
    return pa.Array.from_buffers(pa.string(), len(texts), [None, pa.py_buffer(offsets), data])


def _tails(job: _Text, chunk: list[tuple[str, str, bool]], first_row: int) -> list[str]:
    """The calibrated values to append to each data line of ``chunk``, as text, line by line
    (the csv module splits the fields; a bad value is named with its column and data row)."""
    bodies = [body for body, _, is_data in chunk if is_data]
    if not bodies:
        return []
    src = job.src
    rows = _split(bodies, job.delimiter)
    if len(rows) != len(bodies):
        raise InputError(
            f"{src}: a quoted field runs over several lines near data row {first_row + 1}; "
            "apply copies the file line by line: write the log as .npz or .parquet"
        )
    texts: list[list[str]] = []
    read: Array | None = None
    if job.temp_index is not None and job.temp_name is not None:
        i = job.temp_index
        if any(len(r) <= i for r in rows):
            short = next(k for k, r in enumerate(rows) if len(r) <= i)
            raise InputError(
                f"{src}: data row {first_row + short + 1} has too few fields; fix the file"
            )
        column = np.array([r[i] for r in rows], dtype=str)
        read = to_float(column, job.temp_name, str(src), first_row, decimal=job.decimal)
    t = job.thermal.values(read, job.temp_name)
    for sensor, idx in job.where.items():
        try:
            raw = np.array([[r[i] for i in idx] for r in rows], dtype=str)
        except IndexError:
            short = next(k for k, r in enumerate(rows) if len(r) <= max(idx))
            raise InputError(
                f"{src}: data row {first_row + short + 1} has too few fields; fix the file"
            ) from None
        values = np.column_stack(
            [
                to_float(raw[:, k], job.used[sensor][k], str(src), first_row, decimal=job.decimal)
                for k in range(3)
            ]
        )
        texts += [_text(column) for column in _correct(job.cal, sensor, values, t).T]
    tails = [job.sep.join(fields) for fields in zip(*texts, strict=True)]
    return [t.replace(".", ",") for t in tails] if job.decimal == "," else tails


# ----------------------------------------------------------------------------- tables
def _read_npz(src: Path) -> tuple[dict[str, NDArray[Any]], bool]:
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
    columns: dict[str, NDArray[Any]] = {}
    for name in table.schema.names:
        values = np.asarray(table.column(name).to_numpy(zero_copy_only=False))
        if values.dtype.kind == "O":
            values = np.array(["" if v is None else str(v) for v in values.tolist()], dtype=str)
        columns[name] = values
    return Table(str(src), list(columns), columns)


def _apply_table(
    cal: Calibration,
    src: Path,
    dst: Path,
    sensors: list[str],
    columns: dict[str, str | Sequence[str] | None],
    decimal: str | None = None,
    *,
    table: Table | None = None,
    thermal: _Thermal,
    drive: _Drive | None = None,
) -> dict[str, list[str]]:
    """The calibrated columns through a table read whole (``table``: one already read);
    ``drive`` takes the magnetometer's interference term off with each row's current."""
    fmt_in, fmt_out = output_format(src), output_format(dst)
    arrays: dict[str, NDArray[Any]] = {}
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
        table = read_table(src, decimal=decimal)
    used = _columns_for_apply(table.path, table.names, sensors, columns)
    temp_name = thermal.find(table.path, table.names)
    t = thermal.values(None if temp_name is None else table.numeric(temp_name), temp_name)
    shift = None if drive is None else drive.shift(table)
    fixed = {
        sensor: _correct(
            cal,
            sensor,
            np.column_stack([table.numeric(c) for c in cols])
            - (shift if sensor == "mag" and shift is not None else 0.0),
            t,
        )
        for sensor, cols in used.items()
    }
    reported = _reported(used, temp_name)
    new: dict[str, Array] = {
        f"{c}_cal": column
        for sensor, cols in used.items()
        for c, column in zip(cols, fixed[sensor].T, strict=True)
    }
    _check_new(table.path, table.names, list(new))

    if fmt_out == "npz":
        if fmt_in == "npz":
            out = dict(arrays)
            for sensor, cols in used.items():
                key = _sensor_array(arrays, cols)
                if key is not None:  # an (n, 3) sensor array gets an (n, 3) calibrated one
                    _check_new(table.path, list(arrays), [f"{key}_cal"])
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
    texts = [_text(table.columns[name]) for name in table.names] + [_text(v) for v in new.values()]
    with replacing(dst) as temp, temp.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, delimiter=delimiter, lineterminator="\n")
        writer.writerow(names)
        writer.writerows(zip(*texts, strict=True))
    return reported


def _sensor_array(arrays: dict[str, NDArray[Any]], cols: list[str]) -> str | None:
    """The ``(n, 3)`` array ``cols`` were split from (``accel`` for ``accel_x..z``), if any."""
    key = cols[0][:-2]
    whole = arrays.get(key)
    if whole is None or whole.ndim != 2 or whole.shape[1] != 3:
        return None
    return key if cols == [f"{key}_{axis}" for axis in "xyz"] else None


def _only_columns(src: Path, arrays: dict[str, NDArray[Any]]) -> None:
    """Refuse arrays a table cannot hold (rather than leaving them out of the output)."""
    for key, array in arrays.items():
        if not (array.ndim == 1 or (array.ndim == 2 and array.shape[1] == 3)):
            raise InputError(
                f"{src}: the array {key!r} (shape {array.shape}) is not a column; write the "
                "output as .npz to keep it"
            )


def _write_npz(path: Path, arrays: dict[str, NDArray[Any]], compressed: bool) -> None:
    """``np.savez`` by hand: any key (``np.savez`` reserves ``file``), no pickles."""
    mode = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
    with zipfile.ZipFile(path, "w", compression=mode, allowZip64=True) as archive:
        for key, array in arrays.items():
            with archive.open(f"{key}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(array), allow_pickle=False)
