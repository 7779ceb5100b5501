"""A flight log's accelerometer and gyroscope gain held at the autopilot's calibration.

An autopilot logs its IMU calibrated (PX4's ``sensor_combined``: m/s² and rad/s in the body
frame after its own calibration; ArduPilot's ``IMU``: the same), and a flight turns the vehicle
through little more than its yaw: gravity stays within a few tens of degrees of the body's
down axis, so the accelerometer's gain and bias are not determined (``check_motion`` would
refuse the log) and the gyroscope's gain only about the yaw axis. The flight can determine the
compass (its gain, bias and the field's dip from the headings flown and the tilts of the legs)
and the interference term; holding the others at the autopilot's calibration lets the fit and
the verdict judge that. Held values: the accelerometer's gain ``g₀ I`` (PX4 and ArduPilot scale
their calibration to ``g₀`` = 9.80665 m/s², ``CONSTANTS_ONE_G`` / ``GRAVITY_MSS``) with zero bias,
the gyroscope's gain the identity; the gyroscope's bias is fitted (it drifts with temperature
and the trajectory determines it).
"""

from __future__ import annotations

import numpy as np

from .held_blocks import Held
from .model import LEVER, SLICES, STANDARD_GRAVITY

__all__ = ["AUTOPILOT_BLOCKS", "autopilot_held"]

#: The blocks held for a flight log.
AUTOPILOT_BLOCKS = ("accel.gain", "accel.bias", "gyro.gain")


def autopilot_held(autopilot: str, gravity: float = STANDARD_GRAVITY) -> Held:
    """The blocks of :data:`AUTOPILOT_BLOCKS` at the calibration of ``autopilot`` (its name,
    for the record): the accelerometer's gain ``gravity·I`` (its readings' units per unit of
    gravity), bias zero, the gyroscope's gain the identity (rad/s)."""
    mask = np.zeros(LEVER.stop, dtype=bool)
    mask[SLICES["accel"]] = True
    mask[22:31] = True  # the gyroscope's gain (:data:`.model.SLICES`)
    values = {
        "accel.gain": (gravity * np.eye(3)).ravel(),
        "accel.bias": np.zeros(3),
        "gyro.gain": np.eye(3).ravel(),
    }
    return Held(AUTOPILOT_BLOCKS, values, mask, f"{autopilot}'s calibration (the log's values)")
