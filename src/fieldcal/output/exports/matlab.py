"""The ``matlab`` export: a script in the convention of MATLAB's ``magcal`` (row vectors)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...calibration import Calibration
from .common import (
    NAMES,
    TEMPERATURE_FORMULA,
    comment_header,
    corrections,
    cubic,
    exact,
    temperature_terms,
)

__all__ = ["CONTENT", "FORMULA", "TEMPERATURE_USAGE", "write"]

#: magcal's correction: D is N-by-3 (one raw reading per row), b 1-by-3, A 3-by-3.
FORMULA = "C = (D - b) * A, A = inv(gain).'"
CONTENT = (
    "`A_accel`, `b_accel`, `A_mag`, `b_mag` (and `A_gyro`, `b_gyro`, rad/s, when calibrated; "
    "D N×3, rows are readings; `b` 1×3); with temperature terms `T_<sensor>` (T_ref, T_min, "
    "T_max) and `c_<sensor>` (3×3, row k the order-k coefficients)"
)

#: The bias at the die temperature ``T`` (column vector, one per reading) in the script's terms.
TEMPERATURE_USAGE = (
    "d = min(max(T, T_s(2)), T_s(3)) - T_s(1); b_at = b_s + d * c_s(1,:) + d.^2 * c_s(2,:) "
    "+ d.^3 * c_s(3,:); C = (D - b_at) * A_s"
)


def _matrix(M: NDArray[np.float64]) -> str:
    return "[" + "; ".join(" ".join(exact(v) for v in row) for row in np.atleast_2d(M)) + "]"


def write(cal: Calibration) -> str:
    """A MATLAB script defining ``A_<sensor>`` and ``b_<sensor>`` per calibrated sensor.

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    str
        The script; numbers are exact doubles.
    """
    lines = comment_header(cal, "%")
    lines += [
        f"% Convention of MATLAB's magcal: {FORMULA}",
        "% where D is N-by-3 (one raw reading per row), b is 1-by-3 and A is 3-by-3:",
        "% fieldcal's inv(gain) transposed.",
    ]
    for name, M, b in corrections(cal):
        lines.append(f"% {NAMES[name]}")
        lines.append(f"A_{name} = {_matrix(M.T)};")
        lines.append(f"b_{name} = {_matrix(b)};")
    lines.append("% usage: C_accel = (D_accel - b_accel) * A_accel;")
    terms = temperature_terms(cal)
    if terms:
        lines.append(f"% temperature terms: {TEMPERATURE_FORMULA}")
        lines.append(f"% with T (N-by-1, deg C) and s a sensor: {TEMPERATURE_USAGE}")
    for name, model in terms:
        lines.append(f"% {NAMES[name]}: T_ref, T_min, T_max; c1; c2; c3 (raw units per K^k)")
        lines.append(f"T_{name} = {_matrix(np.array([model.reference, *model.span]))};")
        lines.append(f"c_{name} = {_matrix(cubic(model))};")
    return "\n".join(lines) + "\n"
