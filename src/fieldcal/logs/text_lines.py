"""The lines of a delimited text log: which hold data, their fields as the csv module splits
them, and which fields are numbers as every reader of fieldcal reads them (the text readers of
:mod:`fieldcal.logs.text`, the live line parser of :mod:`fieldcal.logs.stream`, ``apply``).
"""

from __future__ import annotations

import csv
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError

__all__: list[str] = []  # no public names: helpers of the logs room's text readers


def _is_number(text: str) -> bool:
    """A number as every reader of fieldcal reads it: what ``float`` takes, in ASCII and
    without ``_`` (``float`` also takes ``１２``, ``١٢`` and ``1_000``; numpy's and pyarrow's
    parsers do not)."""
    if not text.isascii() or "_" in text:
        return False
    try:
        float(text)
    except ValueError:
        return False
    return True


def _plain(cells: NDArray[np.generic]) -> bool:
    """Text cells free of non-ASCII characters and ``_`` (see :func:`_is_number`); checked
    on their code points at once."""
    if cells.dtype.kind != "U" or cells.size == 0:
        return True
    codes = np.ascontiguousarray(cells).view(np.uint32)
    return bool(codes.max() < 128 and not np.any(codes == ord("_")))


def _numberish(text: str, delimiter: str | None) -> bool:
    """A number, with a decimal point or (when commas do not separate fields) a comma."""
    if _is_number(text):
        return True
    return delimiter != "," and "," in text and _is_number(text.replace(",", "."))


def _sniff_delimiter(header: str, comma: bool = False) -> str | None:
    """The delimiter of a header line: ``,`` ``;`` tab, else blanks (None); never ``,`` in a
    log with decimal commas (``comma``)."""
    for delimiter in (";", "\t") if comma else (",", ";", "\t"):
        if delimiter in header:
            return delimiter
    return None  # whitespace-separated


def _is_data_line(line: str) -> bool:
    """Not blank and not a ``#`` comment (loggers often write banners)."""
    text = line.lstrip()  # (one strip: a line is blank when nothing is left of it)
    return bool(text) and text[0] != "#"


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


def _fields(line: str, delimiter: str | None) -> list[str] | None:
    """The fields of one line, or None when the csv module cannot split it."""
    if delimiter is None:
        return line.split()
    # a line the csv module splits as str.split does (about 5x faster: the head's few hundred
    # lines are split twice per log): no quote, no NUL, no line break but at its end, short
    body = line.rstrip("\r\n")
    if (
        '"' not in body
        and "\r" not in body
        and "\n" not in body
        and "\x00" not in body
        and len(body) < csv.field_size_limit()
    ):
        return body.split(delimiter) if body else []
    try:
        return next(csv.reader([line], delimiter=delimiter), [])
    except csv.Error:
        return None


def _short(text: str, limit: int = 60) -> str:
    return repr(text if len(text) <= limit else text[:limit] + "...")


def _all_numbers(fields: Sequence[str], decimal: str) -> bool:
    return all(
        _is_number(f) or (decimal == "," and _is_number(f.replace(",", "."))) for f in fields
    )
