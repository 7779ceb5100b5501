"""The ``matlab`` export: a script in the convention of MATLAB's ``magcal`` (row vectors)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...calibration import Calibration
from .common import NAMES, comment_header, corrections, exact

__all__ = ["CONTENT", "FORMULA", "write"]

#: magcal's correction: D is N-by-3 (one raw reading per row), b 1-by-3, A 3-by-3.
FORMULA = "C = (D - b) * A, A = inv(gain).'"
CONTENT = (
    "`A_accel`, `b_accel`, `A_mag`, `b_mag` (and `A_gyro`, `b_gyro`, rad/s, when calibrated; "
    "D N×3, rows are readings; `b` 1×3)"
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
    return "\n".join(lines) + "\n"
