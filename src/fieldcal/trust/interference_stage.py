"""The interference stage after a log's calibration: the term fitted with the trajectory held
(:mod:`.interference_fit`), attached to the magnetometer (the verdict's rule
``_interference`` of :mod:`.verdict` judges it, a late check) — unless the continuous fit
already fitted it jointly (:func:`flight_options` gives it the inputs, and for a flight log the
autopilot's calibration to hold and its attitude to start from)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..calibration import Calibration
from ..interference import InterferenceModel
from ..logs import Log
from ..methods.continuous.autopilot_aid import autopilot_held
from .interference_fit import fit_interference, held_trajectory

__all__ = ["flight_options", "with_interference"]


def flight_options(log: Log, hold: object) -> tuple[dict[str, Any], list[str]]:
    """The continuous fit's keywords a log adds, and the notes: its current or throttle
    (``inputs``: the interference term fitted jointly); for a flight log, unless blocks are
    held (``hold``), the accelerometer and the gyroscope's gain held (``prior``): at the
    autopilot's calibration when it calibrated them (the accelerometer in the body frame; its
    attitude estimate, ``attitude``, then starts the fit), else at nominal values (a raw
    sensor-frame stream: gain ``g₀ I``, bias zero, the gyroscope's gain the identity)."""
    options: dict[str, Any] = {}
    notes: list[str] = []
    if log.inputs:
        options["inputs"] = log.inputs
    frame = log.metadata.get("accel_frame", "")
    if not frame or hold:
        return options, notes
    kind = log.metadata.get("log_format", "")
    autopilot = "PX4" if "ULog" in kind else "ArduPilot" if "DataFlash" in kind else "the autopilot"
    if not frame.startswith("body"):  # raw, in the sensor's frame: nominal values
        options["prior"] = autopilot_held(autopilot, source="nominal values (raw readings)")
        notes.append(
            "flight log: the raw accelerometer held at nominal values (gain 9.80665 m/s² per g, "
            "bias 0) and the gyroscope's gain at the identity (a flight's attitudes do not "
            "determine them): its offsets pass into the tilt and the compass; log the calibrated "
            "IMU (sensor_combined) for the autopilot's calibration to be used"
        )
        return options, notes
    options["prior"] = autopilot_held(autopilot)
    notes.append(
        f"flight log: the accelerometer (gain and bias) and the gyroscope's gain held at "
        f"{autopilot}'s calibration (the log's values are calibrated; a flight's attitudes do not "
        "determine them): the fit and the verdict judge the compass and the interference"
    )
    if log.attitude is not None:
        options["attitude"] = log.attitude
        notes.append(f"the fit starts from {autopilot}'s attitude estimate")
    return options, notes


def with_interference(cal: Calibration, log: Log) -> tuple[Calibration, str]:
    """``cal`` with the magnetometer's interference term fitted on ``log`` (its current or
    throttle column, :attr:`Log.inputs`); unchanged when
    the log has no such column or no magnetometer. Returns the note for the user."""
    if not log.inputs or log.mag is None or cal.mag is None:
        return cal, ""
    if cal.mag.interference is not None:  # fitted jointly by the continuous estimator
        return _with_instance(cal, log), _note(cal.mag.interference)
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
    return _with_instance(dataclasses.replace(cal, mag=mag), log), _note(model)


def _note(model: InterferenceModel) -> str:
    what = ", ".join(model.inputs)
    if not model.identifiable:
        return f"interference in {what} not identifiable: {model.reason}"
    how = model.trajectory  # JOINT says "fitted jointly ..."; else where the trajectory came from
    if not how.startswith("fitted"):
        how = f"fitted with the trajectory held ({how})"
    return (
        f"interference in {what} {how}: "
        f"{100 * model.field_share:.0f} % of the Earth's field at {model.span[0, 1]:.3g} "
        f"{model.units[0]}"
    )


def _with_instance(cal: Calibration, log: Log) -> Calibration:
    """``cal`` with a flight log's ``--mag N`` in its options (the exports name it)."""
    if not log.metadata.get("mag_instance", "0").isdigit():
        return cal
    options = {**cal.options, "mag_instance": int(log.metadata.get("mag_instance", "0"))}
    return dataclasses.replace(cal, options=options)
