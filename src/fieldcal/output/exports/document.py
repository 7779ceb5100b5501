"""The ``json`` export: the full calibration document (``docs/json-schema.md``)."""

from __future__ import annotations

from ...calibration import CONVENTIONS, Calibration

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
    """
    return cal.to_json() + "\n"
