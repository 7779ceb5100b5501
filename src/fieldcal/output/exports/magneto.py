"""The ``magneto`` export: Magneto's printout, ``A⁻¹ (h − b)`` on column vectors."""

from __future__ import annotations

from ...calibration import Calibration
from .common import NAMES, comment_header, corrections, exact

__all__ = ["CONTENT", "FORMULA", "write"]

#: Magneto's correction on column vectors; its ``A^-1`` is fieldcal's ``inv(gain)``.
FORMULA = "h_calibrated = A^-1 * (h - b), A^-1 = inv(gain)"
CONTENT = (
    'per sensor "Combined bias (b)" and "Correction for combined scale factors, misalignments '
    'and soft iron (A^-1)"'
)


def write(cal: Calibration) -> str:
    """Magneto's layout, one block per calibrated sensor.

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    str
        The text; numbers are exact doubles.
    """
    lines = comment_header(cal, "#")
    lines.append(f"# Magneto convention: {FORMULA}, h a column vector.")
    for name, M, b in corrections(cal):
        lines += [
            "",
            f"[{NAMES[name]}]",
            "Combined bias (b):",
            "  ".join(f"{exact(v):>22}" for v in b),
            "",
            "Correction for combined scale factors, misalignments and soft iron (A^-1):",
        ]
        lines += ["  ".join(f"{exact(v):>22}" for v in row) for row in M]
    return "\n".join(lines) + "\n"
