"""A log's table as a reader gives it: the columns by name, numbers as float arrays and
text as strings (:class:`Table`), and :func:`to_float` for a column that must hold readings
(a non-numeric value named with its row, and the fix)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .text_lines import (
    _is_number,
    _plain,
    _short,
)

__all__ = ["Table", "to_float"]

Array = NDArray[np.float64]


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
