"""What every export writes: the correction matrices, the provenance lines, exact numbers."""

from __future__ import annotations

from typing import cast

import numpy as np
from numpy.typing import NDArray

from ...calibration import SENSORS, Calibration, SensorCalibration

__all__ = ["NAMES", "corrections", "exact", "provenance"]

Array = NDArray[np.float64]

#: Sensor names as the exported text spells them.
NAMES = {"accel": "accelerometer", "mag": "magnetometer"}


def corrections(cal: Calibration) -> list[tuple[str, Array, Array]]:
    """``(sensor, inv(gain), bias)`` for each calibrated sensor, accelerometer first.

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    list of (str, (3, 3) array, (3,) array)
        The correction ``v = inv(gain) @ (raw − bias)`` of each sensor the result has.
    """
    out: list[tuple[str, Array, Array]] = []
    for name in SENSORS:
        sensor: SensorCalibration | None = getattr(cal, name)
        if sensor is not None:
            inverse = cast(Array, np.linalg.inv(sensor.gain))
            out.append((name, inverse, np.asarray(sensor.bias, dtype=float)))
    return out


def exact(x: float) -> str:
    """The shortest text that reads back as the same double (``1.0``, ``1e+30``).

    Always has a decimal point or an exponent, so no target reads it as an integer.
    """
    return repr(float(x))


def provenance(cal: Calibration) -> list[str]:
    """Lines naming the writer, the method, the calibrated units and any folded axis map."""
    lines = [f"fieldcal {cal.version}, method {cal.method}, created {cal.created}"]
    units = cal.units or {}
    lines.append(
        f"calibrated units: accelerometer {units.get('accel_calibrated', '?')}, "
        f"magnetometer {units.get('mag_calibrated', '?')}"
    )
    if cal.options.get("mag_axes"):
        lines.append(
            f"the magnetometer axis map {cal.options['mag_axes']} is folded in: apply to the raw "
            "columns as logged"
        )
    return lines
