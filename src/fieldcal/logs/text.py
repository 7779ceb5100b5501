"""Delimited text logs (CSV, TSV, blank separated): where the header is, and two readers.

**Layout.** The header is the first line that is not blank and not a ``#`` comment, as long
as it fits the data below it. When it does not (a logger's preamble such as ``Fs,100`` /
``Logger v2`` / ``Date: ...`` above the header, or a header written as a comment,
``# t,ax,ay,...``), the header is looked for just above the data: the line above the first
data row whose field count matches the data rows and which is not all numbers, or else the
last ``#`` line above the data. :func:`layout` decides from the first :data:`HEAD_LINES`
lines that are not blank or comments, and only where the answer is unambiguous; otherwise the
first line stays the header and the errors say what to fix. Decimal commas (``0,123;-9,81``)
are read when asked for (``decimal=","``) or when the columns are separated by ``;`` or tabs
and the numbers in those lines are written with commas and never with points.

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
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .arrow_parser import arrow_parser
from .text_lines import (
    _all_numbers,
    _fields,
    _is_data_line,
    _is_number,
    _numberish,
    _plain,
    _short,
    _sniff_delimiter,
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
    "parse_numbers",
    "read_careful",
    "read_text",
    "to_float",
]

Array = NDArray[np.float64]

#: Longest field of a CSV log: readings and labels are short, and numpy's text arrays would
#: make every cell as wide as the widest one.
LONGEST_FIELD = 1000
#: Lines (not blank, not comments) at the top of a file in which the header is looked for and
#: from which decimal commas and the text columns are recognised.
HEAD_LINES = 200
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


# ----------------------------------------------------------------------------- the table
@dataclass
class Table:
    """Columns of a log as read: numeric columns as float arrays, others as string arrays.

    ``notes`` says what the reader did that the user may want to know (preamble lines skipped,
    decimal commas read as points); ``decimal`` is the decimal mark of the text file, used when
    a text column is read as numbers. ``metadata`` holds what the file says about itself
    (``key: value`` lines above a text log's header, a Parquet file's key-value metadata, an
    ``.npz`` archive's scalar arrays), keys as :func:`metadata_key` writes them.
    """

    path: str
    names: list[str]
    columns: dict[str, NDArray[np.generic]]
    notes: list[str] = field(default_factory=list)
    decimal: str = "."
    metadata: dict[str, str] = field(default_factory=dict)

    @property
    def n_rows(self) -> int:
        """Rows of data (0 for a table without columns)."""
        return 0 if not self.names else len(self.columns[self.names[0]])

    def numeric(self, name: str) -> Array:
        """Column ``name`` as floats; a one-line error naming the first non-numeric value.

        Parameters
        ----------
        name : str

        Returns
        -------
        ndarray of float64

        Raises
        ------
        InputError
            A column of booleans, dates, complex numbers ..., or text that is not numbers.
        """
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
        return to_float(values, name, self.path, decimal=self.decimal)


#: dtype kinds that are not readings, and what to call them.
_NOT_READINGS = {
    "b": "true/false values",
    "c": "complex numbers (take the real part if the imaginary parts are zero)",
    "M": "dates and times",
    "m": "time spans",
    "V": "records",
}


def to_float(
    values: NDArray[np.generic],
    name: str,
    path: str,
    first_row: int = 0,
    *,
    decimal: str = ".",
) -> Array:
    """Text cells as floats: blanks are NaN; a one-line error names the first bad cell.

    Parameters
    ----------
    values : ndarray
        The cells (any dtype numpy can turn into text).
    name, path : str
        The column and the file, for the message.
    first_row : int
        Data-row number of ``values[0]`` minus one (rows are counted from 1).
    decimal : {".", ","}
        The decimal mark; with ``","`` a cell holding a point is not a number (``1.234,5``
        would be a thousands separator, not a reading to guess at).

    Returns
    -------
    ndarray of float64

    Raises
    ------
    InputError
        Naming the column, the value and its data row.
    """
    try:
        original = np.char.strip(values.astype(str))
    except UnicodeDecodeError:
        raise InputError(
            f"{path}: column {name!r} holds bytes that are not text; give readings as numbers"
        ) from None
    text = np.where(original == "", "nan", original)  # an empty field is a missing value
    if decimal == ",":
        text = np.where(np.char.find(text, ".") >= 0, "", np.char.replace(text, ",", "."))
    try:
        if not _plain(text):  # float() reads '１２' and '1_000'; the fast parsers do not
            raise ValueError
        return text.astype(float)
    except ValueError:
        bad = next((i for i, v in enumerate(text) if not _is_number(str(v))), 0)
        raise InputError(
            f"{path}: column {name!r} has a non-numeric value {_short(str(original[bad]))} at "
            f"data row {first_row + bad + 1}; fix or remove that row (or choose other columns)"
        ) from None


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


# ----------------------------------------------------------------------------- layout
@dataclass(frozen=True)
class Layout:
    """Where a text log's header and data are, and how its fields are written.

    ``header_index`` and ``start`` count the file's lines from 0 (blank and comment lines
    included, a byte-order mark removed): the header line, and the first line below it.
    """

    header: str
    header_index: int
    start: int
    delimiter: str | None
    decimal: str = "."
    notes: tuple[str, ...] = ()


def metadata_key(name: str) -> str:
    """A metadata key as fieldcal looks it up: lower case, runs of spaces, dashes and dots as
    ``_`` (``"Serial Number"`` → ``"serial_number"``)."""
    return re.sub(r"[\s.\-]+", "_", name.strip().lower()).strip("_")


#: ``key: value``, ``key = value``, or a two-field ``key,value`` line (``#`` comments too).
_META_LINE = re.compile(r"^[#\s]*([A-Za-z][\w .\-]{0,40}?)\s*(?::|=|,|;|\t)\s*(\S.*?)\s*$")


def metadata_lines(lines: Sequence[str]) -> dict[str, str]:
    """The ``key: value`` pairs in the lines above a text log's header (a logger's preamble or
    ``#`` comments such as ``# device: IMU-0042``); the first of a repeated key wins and a line
    of more than two comma-separated fields is not metadata."""
    out: dict[str, str] = {}
    for line in lines:
        match = _META_LINE.match(line)
        if match is None or line.count(",") > 1:
            continue
        key, value = metadata_key(match.group(1)), match.group(2).strip().strip("\"'")
        if key and value:
            out.setdefault(key, value[:200])
    return out


#: A number written with a decimal comma, and one written with a decimal point.
_COMMA_NUMBER = re.compile(r"[-+]?\d+,\d+(?:[eE][-+]?\d+)?")
_POINT_NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _head(lines: Sequence[str]) -> tuple[Sequence[str], list[int]]:
    """The lines up to the :data:`HEAD_LINES`-th that is not blank or a comment, and where
    those (the head's content) are."""
    content: list[int] = []
    for i, line in enumerate(lines):
        if _is_data_line(line):
            content.append(i)
            if len(content) == HEAD_LINES:
                return lines[: i + 1], content
    return lines, content


def layout(path: Path | str, lines: Sequence[str], decimal: str | None = None) -> Layout:
    """Find the header, the delimiter and the decimal mark of a text log from its first lines.

    Parameters
    ----------
    path : Path or str
        The file, for messages.
    lines : sequence of str
        The file's first lines with their endings (a byte-order mark removed), at least up to
        the :data:`HEAD_LINES`-th that is not blank or a comment (or the whole file).
    decimal : {None, ".", ","}
        The decimal mark; None recognises decimal commas (see the module docstring).

    Returns
    -------
    Layout

    Raises
    ------
    InputError
        An empty file, a preamble that cannot be told from the header, ``decimal=","`` with
        comma-separated columns, or a ``decimal`` that is not ``"."``, ``","`` or None.
    """
    if decimal not in (None, ".", ","):
        raise InputError(f"decimal must be '.' or ',' (or None to recognise it); got {decimal!r}")
    head, content = _head(lines)
    if not content:
        raise InputError(f"{path}: the file is empty; give a CSV with a header line and data rows")
    first = content[0]
    comma = decimal == ","
    delimiter = _sniff_delimiter(head[first], comma)
    found = None if _fits(head, content, delimiter) else _find_header(head, content, comma)
    if found is None:
        below = {_sniff_delimiter(head[i], comma) for i in content[1:6]}
        if delimiter is None and len(below) == 1 and None not in below:
            # a logger's preamble above the header ("Logger v2", "Date: ...")
            raise InputError(
                f"{path}: the first line {_short(head[first].strip())} is not a header (the "
                f"lines below are separated by {below.pop()!r}); delete the lines above the "
                "header (or start them with #)"
            )
        found = Layout(head[first], first, first + 1, delimiter)
    if comma and found.delimiter is None and "," in found.header:
        raise InputError(
            f"{path}: decimal=',' needs columns separated by ';', tabs or blanks (--decimal ,), "
            "but they are separated by ','; write the numbers with points or the columns with ';'"
        )
    return _with_decimal(head, found, decimal)


def _fits(head: Sequence[str], content: list[int], delimiter: str | None) -> bool:
    """Whether the first line is the header: not all numbers and as wide as most rows below.

    A file the careful reader reads today always fits; one that does not fit would be refused,
    so only those are searched for a header elsewhere.
    """
    header = _fields(head[content[0]], delimiter)
    if header is None:
        return True  # the careful reader names the line it cannot split
    if all(_numberish(f, delimiter) for f in header):
        return False
    widths = [len(r) for r in (_fields(head[i], delimiter) for i in content[1:]) if r is not None]
    if not widths:
        return True
    common = int(np.bincount(widths).argmax())
    return len(header) == common


def _find_header(head: Sequence[str], content: list[int], comma: bool) -> Layout | None:
    for delimiter in (";", "\t", None) if comma else (",", ";", "\t", None):
        found = _header_above_data(head, content, delimiter, comma)
        if found is not None:
            return found
    return None


def _header_above_data(
    head: Sequence[str], content: list[int], delimiter: str | None, comma: bool
) -> Layout | None:
    """The header just above the data when fields are separated by ``delimiter``, if
    unambiguous: the data rows are the run of equally wide lines at the end of the head, the
    data starts at the first of them with numbers in every column the last row has numbers in,
    the header is the one line of the run above it (or else the last ``#`` line above it), and
    no line above looks like a data row (that would be data left out)."""
    rows = [_fields(head[i], delimiter) for i in content]
    last = rows[-1]
    if last is None or len(last) < 2:
        return None
    width = len(last)
    k = len(rows) - 1
    while k > 0 and (row := rows[k - 1]) is not None and len(row) == width:
        k -= 1
    numeric = [j for j, f in enumerate(last) if _numberish(f, delimiter)]
    if not numeric:
        return None

    def data_like(row: list[str] | None) -> bool:
        return (
            row is not None
            and len(row) == width
            and all(_numberish(row[j], delimiter) or not row[j].strip() for j in numeric)
        )

    s = next((i for i in range(k, len(rows)) if data_like(rows[i])), None)
    if s is None or any(data_like(rows[i]) for i in range(k)):
        return None
    notes: list[str] = []
    if s > k + 1:
        return None  # two lines could be the header ("t,ax,ay" above "units,g,g")
    if s > k:  # a line of the data's width above the first data row
        index, preamble = content[s - 1], s - 1
        header = head[index]
        fields = rows[s - 1]
    else:  # the last '#' line above the data, with no other line between
        above = content[s - 1] if s else -1
        hashes = [i for i in range(above + 1, content[s]) if head[i].lstrip().startswith("#")]
        if not hashes:
            return None
        index, preamble = hashes[-1], s
        header = head[index].lstrip()[1:]
        fields = _fields(header, delimiter)
        if data_like(fields):
            return None  # a data row commented out
        notes.append(f"header read from the '#' line {index + 1}")
    if (
        fields is None
        or len(fields) != width
        or _sniff_delimiter(header, comma) != delimiter
        or all(_numberish(f, delimiter) for f in fields)
    ):
        return None
    if preamble:
        notes.insert(0, f"skipped {preamble} preamble line(s)")
    return Layout(header, index, index + 1, delimiter, ".", tuple(notes))


def _with_decimal(head: Sequence[str], found: Layout, decimal: str | None) -> Layout:
    delimiter = found.delimiter
    if decimal is not None:
        return Layout(
            found.header, found.header_index, found.start, delimiter, decimal, found.notes
        )
    if delimiter in (";", "\t"):
        cells = [
            f.strip()
            for line in head[found.start :]
            if _is_data_line(line)
            for f in (_fields(line, delimiter) or [])
        ]
        if any(_COMMA_NUMBER.fullmatch(c) for c in cells) and not any(
            _POINT_NUMBER.fullmatch(c) for c in cells
        ):
            notes = (*found.notes, "decimal commas read as points")
            return Layout(found.header, found.header_index, found.start, delimiter, ",", notes)
    return found


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
