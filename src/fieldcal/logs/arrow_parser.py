"""pyarrow in the logs room: loaded on first use, here only; its CSV reader parses the checked
blocks of a text log's fast path (:func:`fieldcal.logs.text.read_text`).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    import pyarrow

__all__ = ["arrow_parser", "float_column", "pyarrow_module"]

Array = NDArray[np.float64]


def pyarrow_module(name: str = "pyarrow") -> ModuleType | None:
    """``pyarrow`` or one of its modules (``"pyarrow.csv"``, ``"pyarrow.parquet"`` ...) loaded
    on first use, or None when pyarrow is not installed: the one place the logs room loads it
    (``import fieldcal`` and ``fieldcal --version`` never do).

    Parameters
    ----------
    name : str

    Returns
    -------
    module or None
    """
    try:
        return importlib.import_module(name)
    except ImportError:
        return None


_Parsed = tuple[list[list[Array]], int, dict[int, NDArray[np.str_]]]


def arrow_parser(
    names: list[str], kinds: list[bool], delimiter: str, decimal: str
) -> Callable[[bytes], _Parsed | None] | None:
    """A parser of checked blocks of a text log's data lines by pyarrow's CSV reader, or None
    when pyarrow is not installed.

    The parser gives each numeric column as pieces (empty fields are NaN), the row count and
    the text columns stripped as the careful reader strips them; None where pyarrow refuses
    the block (a blank-only line, a ragged row, a value it does not read ...), which then goes
    through numpy's parser and, failing that, the careful reader. Only the empty field is
    missing (not ``NA``, ``null`` ...: those are text for the careful reader too).
    """
    pa, pa_csv = pyarrow_module(), pyarrow_module("pyarrow.csv")
    if pa is None or pa_csv is None:
        return None
    read = pa_csv.ReadOptions(column_names=names)
    parse = pa_csv.ParseOptions(
        delimiter=delimiter, quote_char=False, double_quote=False, newlines_in_values=False
    )
    convert = pa_csv.ConvertOptions(
        column_types={
            n: pa.float64() if k else pa.string() for n, k in zip(names, kinds, strict=True)
        },
        null_values=[""],
        strings_can_be_null=False,
        quoted_strings_can_be_null=False,
        decimal_point=decimal,
    )

    def parsed(raw: bytes) -> _Parsed | None:
        try:
            table: pyarrow.Table = pa_csv.read_csv(
                pa.BufferReader(raw), read_options=read, parse_options=parse,
                convert_options=convert,
            )  # fmt: skip
        except (pa.ArrowException, ValueError):
            return None
        numbers = [
            [_doubles(chunk) for chunk in table.column(j).chunks]
            for j, kind in enumerate(kinds)
            if kind
        ]
        cells = {
            j: np.char.strip(np.array(table.column(j).to_pylist(), dtype=str))
            for j, kind in enumerate(kinds)
            if not kind
        }
        return numbers, table.num_rows, cells

    return parsed


def float_column(column: pyarrow.ChunkedArray) -> Array:
    """A pyarrow float64 column (chunked) as one numpy array, nulls as NaN (read from its
    buffers, :func:`_doubles`).

    Parameters
    ----------
    column : pyarrow.ChunkedArray of float64

    Returns
    -------
    (n,) ndarray of float64
    """
    chunks = [_doubles(chunk) for chunk in column.chunks]
    out: Array = np.concatenate(chunks) if chunks else np.empty(0)
    return out


def _doubles(chunk: pyarrow.Array) -> Array:
    """A pyarrow float64 array as numpy's, nulls as NaN; read from its buffers, as pyarrow's
    ``to_numpy`` would import pandas (a second or so) to do it."""
    valid, data = chunk.buffers()
    start, n = chunk.offset, len(chunk)
    values: Array = np.frombuffer(data, dtype=np.float64, count=start + n)[start:]
    if chunk.null_count:
        bits = np.unpackbits(np.frombuffer(valid, dtype=np.uint8), bitorder="little")
        values = np.where(bits[start : start + n] == 0, np.nan, values)
    return values
