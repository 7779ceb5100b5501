"""Where a delimited text log's header is, its delimiter and its decimal mark (:func:`layout`),
and the ``key: value`` lines of a preamble (:func:`metadata_lines`).

The header is the first line that is not blank and not a ``#`` comment, as long as it fits the
data below it. When it does not (a logger's preamble such as ``Fs,100`` / ``Logger v2`` /
``Date: ...`` above the header, or a header written as a comment, ``# t,ax,ay,...``), the
header is looked for just above the data: the line above the first data row whose field count
matches the data rows and which is not all numbers, or else the last ``#`` line above the
data. :func:`layout` decides from the first :data:`HEAD_LINES` lines that are not blank or
comments, and only where the answer is unambiguous; otherwise the first line stays the header
and the errors say what to fix. Decimal commas (``0,123;-9,81``) are read when asked for
(``decimal=","``) or when the columns are separated by ``;`` or tabs and the numbers in those
lines are written with commas and never with points.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .text_lines import (
    _fields,
    _is_data_line,
    _numberish,
    _short,
    _sniff_delimiter,
)

__all__ = ["HEAD_LINES", "Layout", "layout", "metadata_key", "metadata_lines"]

Array = NDArray[np.float64]

#: Lines (not blank, not comments) at the top of a file in which the header is looked for and
#: from which decimal commas and the text columns are recognised.
HEAD_LINES = 200


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
