"""The columns beside the sensors that drive the magnetometer's interference term: battery
current (A) or throttle (0-1), and the autopilot's attitude estimate of a flight log.

Recognised by name (lower case, spaces and dashes as ``_``): current ``current``, ``curr``,
``battery_current``, ``current_a``, ``bat_curr``, ``curr_a``; throttle ``throttle``, ``thr``,
``throttle_out``, ``tho``; or named with ``--current-col`` / ``--throttle-col``. Current is
preferred when both are there (ArduPilot's guidance: the interference is linear in current).
The attitude is the flight readers' ``attitude_qw`` ... ``attitude_qz`` (body → NED, scalar
first, :mod:`.flight`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .flight import ATTITUDE
from .raw_table import Table

__all__ = ["CURRENT_NAMES", "THROTTLE_NAMES", "attitude_of", "drive_inputs"]

Array = NDArray[np.float64]

CURRENT_NAMES = ("current", "curr", "battery_current", "current_a", "bat_curr", "curr_a")
THROTTLE_NAMES = ("throttle", "thr", "throttle_out", "tho")
#: Highest plausible current (A) and throttle: beyond them the column is not what it says.
_LIMITS = {"current": 2000.0, "throttle": 2.0}


def _norm(name: str) -> str:
    return name.strip().lower().replace(" ", "_").replace("-", "_")


def _find(table: Table, given: str | None, names: tuple[str, ...], flag: str) -> str | None:
    if given is not None:
        if not isinstance(given, str) or given not in table.columns:
            raise InputError(
                f"{table.path}: no column {given!r} for {flag}; columns found: "
                + ", ".join(table.names[:12])
            )
        return given
    for name in table.names:
        if _norm(name) in names:
            return name
    return None


def drive_inputs(
    table: Table,
    index: NDArray[np.int64],
    current_col: str | None = None,
    throttle_col: str | None = None,
) -> tuple[dict[str, Array], list[str]]:
    """``{"current": ...}`` or ``{"throttle": ...}`` for the kept rows ``index`` (empty when
    the log has neither), and the notes about it (a column left out for NaN or implausible
    values)."""
    notes: list[str] = []
    for role, given, names, flag in (
        ("current", current_col, CURRENT_NAMES, "--current-col"),
        ("throttle", throttle_col, THROTTLE_NAMES, "--throttle-col"),
    ):
        name = _find(table, given, names, flag)
        if name is None:
            continue
        values = table.numeric(name)[index]
        bad = ~np.isfinite(values)
        if bad.all() or np.any(np.abs(values[~bad]) > _LIMITS[role]):
            notes.append(f"{role} column {name!r} has no usable values: no interference term")
            continue
        if bad.any():  # a battery monitor logs slower than the sensors: hold the last value
            good = np.flatnonzero(~bad)
            values = np.interp(np.arange(len(values)), good, values[good])
            notes.append(f"{role} column {name!r}: {int(bad.sum())} missing values interpolated")
        return {role: values}, notes
    return {}, notes


def attitude_of(table: Table, index: NDArray[np.int64]) -> Array | None:
    """The attitude quaternions (n, 4) of the kept rows, normalised; ``None`` without them."""
    if not all(name in table.columns for name in ATTITUDE):
        return None
    q = np.column_stack([table.numeric(name)[index] for name in ATTITUDE])
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    if not (np.all(np.isfinite(q)) and np.all(norm > 0.5)):
        return None
    return q / norm
