"""The verdict's reasons that come from the input rather than the fit: a gain no physical unit
explains (``unexplained_scale``: the fit itself sees normalised readings, so this is judged on
the calibration in the user's units) and a temperature column left out as unusable
(``temperature_ignored``)."""

from __future__ import annotations

import dataclasses

from ..calibration import Calibration, Reason
from ..logs.log import Log
from .verdict import reason, unexplained_scales, with_reasons

__all__ = ["with_input_reasons", "with_scale_reasons"]


def with_scale_reasons(cal: Calibration) -> Calibration:
    """``cal`` with ``unexplained_scale`` for each sensor whose gain no unit explains.

    Parameters
    ----------
    cal : Calibration
        In the user's units.

    Returns
    -------
    Calibration
    """
    found = [reason(c, **v) for c, v in unexplained_scales(cal, ("accel", "mag", "gyro"))]
    if not found or cal.verdict is None:
        return cal
    return dataclasses.replace(cal, verdict=with_reasons(cal.verdict, found))


def with_input_reasons(cal: Calibration, log: Log) -> Calibration:
    """``cal`` with the input's reasons added to its verdict (unchanged without any).

    Parameters
    ----------
    cal : Calibration
        A calibration from ``log``, the gyroscope's fit included.
    log : Log

    Returns
    -------
    Calibration
    """
    cal = with_scale_reasons(cal)  # the gyroscope's too, fitted after the field sensors
    found: list[Reason] = []
    if log.temperature_ignored is not None:
        column, why = log.temperature_ignored
        found.append(reason("temperature_ignored", column=column, why=why))
    if not found or cal.verdict is None:
        return cal
    return dataclasses.replace(cal, verdict=with_reasons(cal.verdict, found))
