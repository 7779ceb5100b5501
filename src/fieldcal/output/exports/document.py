"""The ``json`` export: the full calibration document (``docs/json-schema.md``)."""

from __future__ import annotations

from ...calibration import CONVENTIONS, Calibration
from .common import corrections

__all__ = ["CONTENT", "FORMULA", "write"]

#: The document states its own correction among its ``conventions``.
FORMULA = CONVENTIONS["correction"]
CONTENT = "the full calibration, readable by `fieldcal.Calibration.from_json`"


def write(cal: Calibration) -> str:
    """The calibration's versioned JSON document.

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    str
        :meth:`Calibration.to_json` with a final newline.

    Raises
    ------
    ValueError
        A gain or bias that is not finite or a singular gain (as every export).
    """
    corrections(cal)  # the same refusal as every other format: a correction must exist
    return cal.to_json() + "\n"
