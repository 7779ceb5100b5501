"""The interference stage after a log's calibration: the term fitted with the trajectory held
(:mod:`.interference_fit`), attached to the magnetometer (the verdict's rule
``_interference`` of :mod:`.verdict` judges it, a late check)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..calibration import Calibration
from ..logs import Log
from .interference_fit import fit_interference, held_trajectory

__all__ = ["with_interference"]


def with_interference(cal: Calibration, log: Log) -> tuple[Calibration, str]:
    """``cal`` with the magnetometer's interference term fitted on ``log`` (its current or
    throttle column, :attr:`Log.inputs`); unchanged when
    the log has no such column or no magnetometer. Returns the note for the user."""
    if not log.inputs or log.mag is None or cal.mag is None:
        return cal, ""
    rotations, source = held_trajectory(
        log.attitude, log.time, np.asarray(cal.rotations), cal.options.get("epoch_step")
    )
    if rotations is None:
        return cal, f"interference term not fitted: {source}"
    model = fit_interference(
        log.mag,
        rotations,
        log.inputs,
        start_gain=cal.mag.gain,
        start_bias=cal.mag.bias,
        temperature=log.temperature,
        trajectory=source,
    )
    mag = dataclasses.replace(cal.mag, interference=model)
    what = ", ".join(model.inputs)
    if model.identifiable:
        note = (
            f"interference in {what} fitted with the trajectory held ({source}): "
            f"{100 * model.field_share:.0f} % of the Earth's field at {model.span[0, 1]:.3g} "
            f"{model.units[0]}"
        )
    else:
        note = f"interference in {what} not identifiable: {model.reason}"
    options = dict(cal.options)
    if log.metadata.get("mag_instance", "0").isdigit():  # a flight log's --mag N, for exports
        options["mag_instance"] = int(log.metadata.get("mag_instance", "0"))
    return dataclasses.replace(cal, mag=mag, options=options), note
