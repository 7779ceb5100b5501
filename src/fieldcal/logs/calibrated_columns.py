"""What applying a calibration to a log needs whatever the format: the sensors' columns found
in the header (named or recognised), the temperature terms' column or constant
(:class:`Thermal`), the magnetometer's interference shift per row (:class:`Drive`), the
corrected values and their text (the shortest that reads back as the same value).

Used by :mod:`fieldcal.logs.apply` (tables read whole) and :mod:`fieldcal.logs.streamed_text`
(text streamed in chunks).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..interference import InterferenceModel
from .columns import explicit_columns, recognise_columns
from .drive_inputs import drive_inputs
from .readers import Table

if TYPE_CHECKING:
    from ..calibration import Calibration


__all__ = [
    "SHOWN",
    "Drive",
    "Thermal",
    "as_text",
    "check_new_columns",
    "columns_for_apply",
    "corrected",
    "reported_columns",
    "shown_header",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Drive:
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
class Thermal:
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


def reported_columns(used: dict[str, list[str]], temp: str | None) -> dict[str, list[str]]:
    return used if temp is None else {**used, "temperature": [temp]}


def columns_for_apply(
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
            raise InputError(
                f"{path}: no column {missing[0]!r}; columns found: {shown_header(header)}"
            )
        used[sensor] = cols
    if not used:
        raise InputError(
            f"{path}: no columns for the calibrated sensors ({', '.join(sensors)}) among "
            f"{shown_header(header)}; pass --accel-cols/--mag-cols/--gyro-cols"
        )
    return used


#: A message shows at most this many characters of a file's header.
SHOWN = 80


def shown_header(header: Sequence[str]) -> str:
    """The header's names for a message: control characters escaped, cut after
    :data:`SHOWN` characters (a file of NUL bytes is one 10,000-character name)."""
    text = ", ".join(header)
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text[: SHOWN * 4])
    if len(text) > SHOWN:
        return f"{text[:SHOWN]}... ({len(header)} column(s))"
    return text


def check_new_columns(path: str, existing: Sequence[str], new: Sequence[str]) -> None:
    clash = [name for name in new if name in existing]
    if clash:
        raise InputError(
            f"{path}: already has the column {clash[0]!r}: the log was calibrated before; "
            "apply the calibration to the raw log"
        )


def corrected(
    cal: Calibration, sensor: str, raw: Array, temperature: Array | float | None = None
) -> Array:
    if sensor == "accel":
        return cal.correct_accel(raw, temperature)
    if sensor == "gyro":
        return cal.correct_gyro(raw, temperature)
    return cal.correct_mag(raw, temperature)


def as_text(values: NDArray[Any]) -> list[str]:
    """Each value as the shortest text that reads back as the same value of its type."""
    if values.dtype == np.float64:
        return list(map(repr, values.tolist()))  # Python's repr: shortest round trip
    if values.dtype.kind == "O":
        return ["" if v is None else str(v) for v in values.tolist()]
    return values.astype(str).tolist()  # numpy's shortest round trip for float32 too
