"""Delimited text logs (CSV, TSV, blank separated): two readers, the careful and the fast.

**Layout.** Where the header is, the delimiter and the decimal mark:
:func:`~fieldcal.logs.text_layout.layout` (exported here as before).

**Readers.** :func:`read_careful` is the reference: it splits every line with the csv module,
checks every limit (:data:`LONGEST_FIELD`, duplicate names, ragged rows) and its one-line
errors name the row, the column, what was found and the fix. It holds the whole file as Python
strings (about 1 GB per million rows of ten columns), so :func:`read_text` first tries a fast
path: blocks of whole lines, checked for what the careful reader would read differently (a
quote, non-ASCII data, a long line, a lone carriage return ...), parsed by pyarrow's CSV reader
(files of :data:`ARROW_MIN_BYTES` or more, or any size once pyarrow is loaded; blocks of
:data:`ARROW_BLOCKS` x :data:`BLOCK_BYTES`) or by numpy's C reader (:func:`numpy.loadtxt`;
smaller files, blank-separated columns, blocks with comment lines or that pyarrow refuses), the
numeric columns straight into one float array, the text columns (pose labels, device names)
split apart. The fast path gives up on anything it would not read exactly as the careful
reader (a value neither parser reads, a ragged row ...), and the careful reader then reads
the file and explains it: all give the same :class:`Table` or the same error
(``tests/logs/test_readers.py`` checks this on random files, with either parser).
Giving up costs the careful reader's time and memory (a stray quote in ten million rows would
need some 10 GB), so the fast path itself reads what well-formed logs hold: blank and comment
lines, CRLF endings, a byte-order mark, empty fields (NaN), text columns, decimal commas.
"""

from __future__ import annotations

import csv
import os
import re
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .arrow_parser import arrow_parser
from .raw_table import Table, to_float
from .text_layout import (
    HEAD_LINES,
    Layout,
    layout,
    metadata_key,
    metadata_lines,
)
from .text_lines import (
    _all_numbers,
    _fields,
    _is_data_line,
    _plain,
    _short,
    _split,
)

__all__ = [
    "ARROW_BLOCKS",
    "ARROW_MIN_BYTES",
    "ARROW_MIN_BYTES_LOADED",
    "BLOCK_BYTES",
    "HEAD_LINES",
    "LONGEST_FIELD",
    "PROGRESS_ROWS",
    "Layout",
    "Table",
    "layout",
    "metadata_key",
    "metadata_lines",
    "parse_numbers",
    "read_careful",
    "read_text",
    "to_float",
]

Array = NDArray[np.float64]

#: Longest field of a CSV log: readings and labels are short, and numpy's text arrays would
#: make every cell as wide as the widest one.
LONGEST_FIELD = 1000
#: Bytes the fast path parses at a time (whole lines): small enough that the text in flight is
#: a few MB beside the arrays, large enough that numpy's per-call cost does not show.
BLOCK_BYTES = 1 << 21
#: Rows between two progress reports of :func:`read_text`.
PROGRESS_ROWS = 1_000_000
#: Files at least this large are parsed by pyarrow's CSV reader (where it is installed): its
#: import (about 0.1 s) pays off above a few MB; smaller files, and blank-separated logs, go
#: through numpy's parser.
ARROW_MIN_BYTES = 1 << 22
#: The same threshold once this process has loaded pyarrow's CSV reader (a batch worker, any
#: log after a large one): its import is paid, and it parses a small log in about half the time.
ARROW_MIN_BYTES_LOADED = 0
#: pyarrow parses blocks of this many times :data:`BLOCK_BYTES` (split among its threads): 4 MB
#: reads as fast as 16 MB (on one CPU or two) with about 40 MB less memory in flight at 10⁶ rows
#: (pyarrow's pool keeps what a block's table used).
ARROW_BLOCKS = 2


# ----------------------------------------------------------------------------- small helpers
def _check_header(path: Path | str, header: list[str]) -> None:
    seen: dict[str, int] = {}
    for j, name in enumerate(header):
        if name in seen:
            label = f"column name {_short(name)}" if name else "an empty column name"
            raise InputError(
                f"{path}: {label} appears twice (columns {seen[name] + 1} and {j + 1}); give "
                "every column its own name"
            )
        seen[name] = j


def _column(cells: Sequence[str], decimal: str) -> NDArray[np.generic]:
    """One column of cells as floats (blanks are NaN) or, if any cell is not a number, as its
    stripped text (labels, device names; checked when used)."""
    text = np.array(cells, dtype=str)
    if decimal == "." and _plain(text):
        try:
            return text.astype(float)  # float() takes surrounding blanks
        except ValueError:
            pass
    column = np.char.strip(text)
    filled = np.where(column == "", "nan", column)
    if decimal == ",":
        if np.any(np.char.find(filled, ".") >= 0):
            return column  # a point in a decimal-comma log: not a number to guess at
        filled = np.char.replace(filled, ",", ".")
    if not _plain(filled):
        return column  # '１２', '1_000': text, refused by name where a reading is needed
    try:
        return filled.astype(float)
    except ValueError:
        return column


def _is_float_column(cells: Sequence[str], decimal: str) -> bool:
    """Whether :func:`_column` reads the cells as numbers: at once when every cell is a plain
    number (ASCII, no ``_`` or NUL, what ``float`` reads: numpy's text-to-float cast calls it,
    and only drops trailing NULs), else by :func:`_column` itself."""
    if decimal == ".":
        joined = "".join(cells)
        if joined.isascii() and "_" not in joined and "\x00" not in joined:
            try:
                for cell in cells:
                    float(cell)
            except ValueError:
                pass
            else:
                return True
    return _column(cells, decimal).dtype.kind == "f"


# ----------------------------------------------------------------------------- careful reader
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


def _read_lines(path: Path) -> list[str]:
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            return handle.readlines()
    except UnicodeDecodeError:
        raise InputError(
            f"{path}: not a text file; give a CSV with a header line (or .npz / .parquet)"
        ) from None


def read_careful(path: str | Path, *, decimal: str | None = None) -> Table:
    """Read a delimited text log with every check, holding the whole file as Python strings.

    The reference for :func:`read_text` and the reader that explains what the fast path
    gives up on. See the module docstring for the header variants.

    Parameters
    ----------
    path : str or Path
    decimal : {None, ".", ","}
        The decimal mark; None recognises decimal commas.

    Returns
    -------
    Table

    Raises
    ------
    InputError
        One line naming the row, the column, what was found and the fix.
    """
    path = Path(path)
    raw = _read_lines(path)
    found = layout(path, raw, decimal)
    lines = [found.header, *(line for line in raw[found.start :] if _is_data_line(line))]
    delimiter, decimal = found.delimiter, found.decimal
    rows = _split(lines, delimiter, str(path))
    if len(rows) == len(lines):  # (a quoted field across lines would shift the numbering)
        _check_lengths(path, lines, rows)
    elif any(len(f) > LONGEST_FIELD for r in rows for f in r):
        raise InputError(
            f"{path}: a field is longer than {LONGEST_FIELD:,} characters (an unmatched quote "
            "joins lines); fix the quoting or cut the file"
        )
    header = [h.strip() for h in rows[0]]
    if _all_numbers(header, decimal):
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
    # column by column: a text array is as wide as its longest cell, so one long cell widens
    # its own column only
    columns = {
        name: _column(cells, decimal)
        for name, cells in zip(header, zip(*body, strict=True), strict=True)
    }
    meta = metadata_lines(raw[: found.header_index])
    return Table(str(path), header, columns, list(found.notes), decimal, meta)


# ----------------------------------------------------------------------------- fast reader
class _UnusualError(Exception):
    """Something the fast path would not read exactly as :func:`read_careful` does."""


#: An empty (or blank) field next to a delimiter, per delimiter (a tab field may hold spaces
#: only: a tab is the delimiter).
_EMPTY = {
    d: re.compile(
        rf"(?:^|(?<={re.escape(d)})){blank}*(?={re.escape(d)})|(?<={re.escape(d)}){blank}*(?=\r?$)",
        re.MULTILINE,
    )
    for d, blank in ((",", "[ \t]"), (";", "[ \t]"), ("\t", "[ ]"))
}
#: Control characters that Python's ``str.split()`` takes for blanks and numpy does not.
_CONTROL = re.compile(rb"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")
#: A window of this many bytes holds a line break wherever it is placed on a line boundary if
#: no line is longer than 2 x 496 - 2 = 990 < LONGEST_FIELD characters.
_WINDOW = 496


def _short_lines(raw: bytes) -> bool:
    """Whether every aligned window of :data:`_WINDOW` bytes holds a line break, which bounds
    every line (and so every field) of ``raw`` below :data:`LONGEST_FIELD` characters."""
    n = len(raw) // _WINDOW * _WINDOW
    if n == 0:
        return True
    breaks = np.frombuffer(raw, dtype=np.uint8, count=n) == 10
    # eight booleans per 64-bit word: any() over a window's words is any() over its bytes
    return bool(breaks.view(np.uint64).reshape(-1, _WINDOW // 8).any(axis=1).all())


#: Bytes :func:`_read_head` reads at once (more when its lines are long): some 200 lines of a
#: typical log's 50-100 characters.
_HEAD_BYTES = 1 << 14


def _read_head(handle: BinaryIO) -> tuple[list[str], int]:
    """The first lines as text (up to :data:`HEAD_LINES` data lines) and the byte-order mark's
    length; anything but short UTF-8 lines ending in ``\\n`` is for the careful reader (quotes
    are allowed here: a header may quote its names; the data blocks are checked again).
    Plain ASCII is read as one block and split (:func:`_ascii_head`), anything else line by
    line (:func:`_head_by_line`): the same lines, or the same giving up."""
    bom = 3 if handle.read(3) == b"\xef\xbb\xbf" else 0
    size = _HEAD_BYTES
    while size <= 16 * _HEAD_BYTES:
        handle.seek(bom)
        raw = handle.read(size)
        lines = _ascii_head(raw, at_end=len(raw) < size)
        if lines is not None:
            return lines, bom
        if len(raw) < size or not raw.isascii():
            break  # the whole file, or text with other characters: line by line
        size *= 4
    handle.seek(bom)
    return _head_by_line(handle), bom


def _ascii_head(raw: bytes, at_end: bool) -> list[str] | None:
    """The head's lines from ``raw``, the file's first bytes (``at_end``: all of it), when its
    whole lines are plain ASCII (``\\r`` only before ``\\n``, no NUL): split at once, as
    :func:`_head_by_line` would read them one by one. None when they are not, or do not reach
    the :data:`HEAD_LINES`-th data line before the end of ``raw``: read them line by line."""
    whole = raw if at_end else raw[: raw.rfind(b"\n") + 1]
    if not whole or not whole.isascii() or b"\x00" in whole:
        return None
    if b"\r" in whole and whole.count(b"\r") != whole.count(b"\r\n"):
        return None
    pieces = whole.decode("ascii").split("\n")
    last = pieces.pop()  # "" after a final line break; at the end, a last line without one
    lines = [piece + "\n" for piece in pieces]
    if last:
        lines.append(last)
    count = 0
    for i, line in enumerate(lines):
        count += _is_data_line(line)
        if count == HEAD_LINES:
            del lines[i + 1 :]
            break
    else:
        if not at_end:
            return None
    if max(map(len, lines)) > LONGEST_FIELD:  # bytes: ASCII
        raise _UnusualError
    return lines


def _head_by_line(handle: BinaryIO) -> list[str]:
    """:func:`_read_head`'s lines read one by one, each checked."""
    lines: list[str] = []
    count = 0
    while count < HEAD_LINES:
        raw = handle.readline(LONGEST_FIELD + 2)
        if not raw:
            break
        if len(raw) > LONGEST_FIELD or b"\r" in raw[:-2] or b"\x00" in raw:
            raise _UnusualError
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise _UnusualError from None
        if line.endswith("\r"):
            raise _UnusualError  # a lone carriage return ends lines for the careful reader
        lines.append(line)
        count += _is_data_line(line)
    return lines


def _numbers(
    lines: list[str], delimiter: str | None, usecols: list[int] | None, width: int
) -> Array:
    """numpy's C parser on whole lines (``width`` columns come out); blank fields retried as
    NaN; anything else unusual."""
    for attempt in range(3):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                return np.loadtxt(
                    lines,
                    dtype=np.float64,
                    delimiter=delimiter,
                    comments=None,
                    quotechar=None,
                    usecols=usecols,
                    ndmin=2,
                )
        except Warning:  # "input contained no data": blank lines only; anything else unusual
            if any(line.strip() for line in lines):
                raise _UnusualError from None
            return np.empty((0, width))
        except ValueError:
            if attempt == 2 or delimiter is None:
                raise _UnusualError from None
            # blank fields as NaN (blank lines left out first: they are no rows of NaN), the
            # empty ones by plain replacing, then those holding blanks by a slower pattern
            joined = "\n".join(line for line in lines if _is_data_line(line))
            if attempt == 0:
                lines = _fill_empty(joined, delimiter).split("\n")
            else:
                lines = _EMPTY[delimiter].sub("nan", joined).split("\n")
    raise AssertionError("unreachable")


def _fill_empty(text: str, delimiter: str) -> str:
    """``text`` with every empty field (nothing between two delimiters, or between a delimiter
    and the line's start or end) written ``nan``; fields of blanks are left alone."""
    d = delimiter
    text = text.replace(d + d, f"{d}nan{d}").replace(d + d, f"{d}nan{d}")  # runs: twice
    text = text.replace("\n" + d, f"\nnan{d}").replace(d + "\r\n", f"{d}nan\r\n")
    text = text.replace(d + "\n", f"{d}nan\n")
    if text.startswith(d):
        text = "nan" + text
    if text.endswith(d):  # the last line, without a line break
        text += "nan"
    return text


def parse_numbers(lines: list[str], delimiter: str | None, usecols: list[int]) -> Array | None:
    """The numbers of whole data lines by numpy's C parser, blank fields as NaN.

    Parameters
    ----------
    lines : list of str
        Data lines (a line ending at the end of each is allowed), decimal points, no quotes.
    delimiter : str or None
        ``","``, ``";"``, a tab, or None for blanks.
    usecols : list of int
        The columns to read (fields beyond them are not looked at).

    Returns
    -------
    ndarray of float64, shape (rows, columns), or None
        None when numpy refuses a line (a value it does not parse, too few fields ...): the
        caller then reads those lines the careful way, which names the problem.
    """
    try:
        return _numbers(lines, delimiter, usecols, len(usecols))
    except _UnusualError:
        return None


class _Columns:
    """The numeric columns of the rows read so far, one float array grown as needed.

    Stored column by column (``values[j]`` is column ``j``): each block is transposed while it
    is in cache, so the table's columns come out contiguous and stacking a sensor's three
    columns later reads 24 bytes a row, not every row's whole width three times.
    """

    def __init__(self, width: int, capacity: int) -> None:
        self.values = np.empty((width, max(capacity, 1024)))
        self.n = 0

    def _room(self, k: int) -> None:
        if self.n + k > self.values.shape[1]:
            # an underestimate of the rows: grow by half (rare: the estimate is generous)
            grown = np.empty((self.values.shape[0], int(1.5 * self.values.shape[1]) + k))
            grown[:, : self.n] = self.values[:, : self.n]
            self.values = grown

    def add(self, block: Array) -> None:
        """Add the rows of ``block`` (rows x columns)."""
        k = len(block)
        self._room(k)
        self.values[:, self.n : self.n + k] = block.T
        self.n += k

    def add_columns(self, columns: list[list[Array]], k: int) -> None:
        """Add ``k`` rows given column by column, each column as consecutive pieces."""
        self._room(k)
        for j, pieces in enumerate(columns):
            at = self.n
            for piece in pieces:
                self.values[j, at : at + len(piece)] = piece
                at += len(piece)
        self.n += k


def _read_fast(path: Path, decimal: str | None, on_progress: Callable[[str], None] | None) -> Table:
    size = os.stat(path).st_size
    with path.open("rb") as handle:
        head, bom = _read_head(handle)
        try:
            found = layout(path, head, decimal)
        except InputError:
            raise _UnusualError from None
        delimiter, decimal = found.delimiter, found.decimal
        fields = _fields(found.header, delimiter)
        if fields is None or (
            # quoted names ("t","ax",... as R and pyarrow write them): the quotes must close on
            # the header line, which the careful reader splits together with the data lines
            delimiter is not None
            and '"' in found.header
            and sum(1 for _ in csv.reader([found.header, "0"], delimiter=delimiter)) != 2
        ):
            raise _UnusualError
        names = [h.strip() for h in fields]
        data_lines = [line for line in head[found.start :] if _is_data_line(line)]
        sample = [_fields(line, delimiter) for line in data_lines]
        if (
            not sample
            or len(set(names)) != len(names)
            or _all_numbers(names, decimal)
            or any(row is None or len(row) != len(names) for row in sample)
        ):
            raise _UnusualError  # no data in the head, a duplicate name, a ragged row ...
        kinds = [
            _is_float_column([row[j] for row in sample if row is not None], decimal)
            for j in range(len(names))
        ]
        numeric = [j for j, is_number in enumerate(kinds) if is_number]
        text = [j for j, is_number in enumerate(kinds) if not is_number]
        offset = bom + sum(len(line.encode("utf-8")) for line in head[: found.start])
        per_row = sum(map(len, data_lines)) / len(data_lines)
        handle.seek(offset)
        columns = _Columns(len(numeric), int(1.25 * (size - offset) / max(per_row, 2.0)))
        texts: dict[int, list[NDArray[np.str_]]] = {j: [] for j in text}
        reported = 0
        arrow = None
        loaded = "pyarrow.csv" in sys.modules
        if delimiter is not None and size - offset >= (
            ARROW_MIN_BYTES_LOADED if loaded else ARROW_MIN_BYTES
        ):
            arrow = arrow_parser(names, kinds, delimiter, decimal)
        block_bytes = BLOCK_BYTES * (ARROW_BLOCKS if arrow is not None else 1)
        while raw := handle.read(block_bytes):
            if not raw.endswith(b"\n"):
                raw += handle.readline()
            _check_block(raw, delimiter, decimal)
            # comment lines, and "nan(...)" (which pyarrow reads as NaN and float() refuses),
            # go through numpy's parser, as does a block pyarrow refuses
            parsed = None if arrow is None or b"#" in raw or b"(" in raw else arrow(raw)
            if parsed is not None:
                columns.add_columns(parsed[0], parsed[1])
                cells_of = parsed[2]
            else:
                block, cells_of = _block(raw, delimiter, decimal, len(names), numeric, text)
                columns.add(block)
            for j, cells in cells_of.items():
                texts[j].append(cells)
            if on_progress is not None and columns.n >= reported + PROGRESS_ROWS:
                reported = columns.n // PROGRESS_ROWS * PROGRESS_ROWS
                on_progress(f"reading {path.name}: {reported:,} rows")
    n = columns.n
    if n == 0:
        raise _UnusualError
    if on_progress is not None and reported != n:
        on_progress(f"reading {path.name}: {n:,} rows")
    values = columns.values
    out: dict[str, NDArray[np.generic]] = {}
    for j, name in enumerate(names):
        out[name] = values[numeric.index(j), :n] if kinds[j] else np.concatenate(texts[j])
    meta = metadata_lines(head[: found.header_index])
    return Table(str(path), names, out, list(found.notes), decimal, meta)


def _check_block(raw: bytes, delimiter: str | None, decimal: str) -> None:
    """:class:`_UnusualError` unless the block of whole lines is what both fast parsers read
    exactly as the careful reader: no quotes, ASCII, short lines, ``\\n`` or ``\\r\\n`` endings,
    no points in a decimal-comma log."""
    if (
        b'"' in raw
        or b"\x00" in raw
        or not raw.isascii()
        or not _short_lines(raw)
        or (delimiter is None and _CONTROL.search(raw) is not None)
        or (b"\r" in raw and raw.count(b"\r") != raw.count(b"\r\n"))
        or (decimal == "," and b"." in raw)
    ):
        raise _UnusualError


def _block(
    raw: bytes,
    delimiter: str | None,
    decimal: str,
    width: int,
    numeric: list[int],
    text: list[int],
) -> tuple[Array, dict[int, NDArray[np.str_]]]:
    """The numeric columns (rows x len(numeric)) and the text columns of one block of whole
    lines (checked by :func:`_check_block`) by numpy's parser, or :class:`_UnusualError`."""
    chunk = raw.decode("ascii")
    # (empty fields are rare: numpy stops at one, and _numbers writes them "nan" and retries)
    if text or "#" in chunk:
        lines = [line for line in chunk.split("\n") if _is_data_line(line)]
        numbers = [line.replace(",", ".") for line in lines] if decimal == "," else lines
    else:  # blank lines are skipped by numpy too
        lines = numbers = (chunk.replace(",", ".") if decimal == "," else chunk).split("\n")
    if numeric:
        values = _numbers(numbers, delimiter, numeric if text else None, len(numeric))
    else:  # text columns only
        values = np.empty((len(lines), 0))
    if values.shape[1] != len(numeric) and len(values):
        raise _UnusualError  # a row count that changed on the first line
    cells: dict[int, NDArray[np.str_]] = {}
    if text:
        rows = [line.split(delimiter) for line in lines]
        if len(values) != len(rows) or any(len(row) != width for row in rows):
            raise _UnusualError
        cells = {j: np.char.strip(np.array([row[j] for row in rows], dtype=str)) for j in text}
    return values, cells


def read_text(
    path: str | Path,
    *,
    decimal: str | None = None,
    on_progress: Callable[[str], None] | None = None,
) -> Table:
    """Read a delimited text log: the fast path, or the careful reader where it gives up.

    Parameters
    ----------
    path : str or Path
    decimal : {None, ".", ","}
        The decimal mark; None recognises decimal commas (``;`` or tab separated columns with
        numbers like ``0,123`` and none like ``0.123``).
    on_progress : callable, optional
        Told ``"reading <name>: <rows> rows"`` every :data:`PROGRESS_ROWS` rows and at the end.

    Returns
    -------
    Table
        The same table :func:`read_careful` gives (numeric columns may be views of one array).

    Raises
    ------
    InputError
        The careful reader's one-line error.
    """
    path = Path(path)
    if decimal not in (None, ".", ","):
        raise InputError(f"decimal must be '.' or ',' (or None to recognise it); got {decimal!r}")
    try:
        return _read_fast(path, decimal, on_progress)
    except _UnusualError:
        pass
    table = read_careful(path, decimal=decimal)
    if on_progress is not None:
        on_progress(f"reading {path.name}: {table.n_rows:,} rows")
    return table
