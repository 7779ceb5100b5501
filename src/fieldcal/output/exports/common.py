"""What every export writes: the correction matrices, the provenance lines, exact numbers."""

from __future__ import annotations

from typing import cast

import numpy as np
from numpy.typing import NDArray

from ...calibration import GYRO, SENSORS, Calibration, SensorCalibration

__all__ = ["NAMES", "comment_header", "corrections", "exact", "provenance"]

Array = NDArray[np.float64]

#: Sensor names as the exported text spells them.
NAMES = {"accel": "accelerometer", "mag": "magnetometer", "gyro": "gyroscope"}


def corrections(cal: Calibration) -> list[tuple[str, Array, Array]]:
    """``(sensor, inv(gain), bias)`` for each calibrated sensor: accelerometer, magnetometer,
    then the gyroscope (its correction gives rad/s).

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    list of (str, (3, 3) array, (3,) array)
        The correction ``v = inv(gain) @ (raw − bias)`` of each sensor the result has.

    Raises
    ------
    ValueError
        A gain or bias that is not finite, a singular gain, or a correction that overflows:
        no target can represent it, so every export refuses it in one line.
    """
    out: list[tuple[str, Array, Array]] = []
    for name in (*SENSORS, GYRO):
        sensor: SensorCalibration | None = getattr(cal, name)
        if sensor is None:
            continue
        gain = np.asarray(sensor.gain, dtype=float)
        bias = np.asarray(sensor.bias, dtype=float)
        what = f"cannot export: the {NAMES[name]}'s"
        if not (np.isfinite(gain).all() and np.isfinite(bias).all()):
            raise ValueError(
                f"{what} gain or bias is not finite (NaN or infinity); calibrate again"
            )
        try:
            inverse = cast(Array, np.linalg.inv(gain))
        except np.linalg.LinAlgError:
            raise ValueError(
                f"{what} gain is singular, so there is no correction inv(gain); calibrate again"
            ) from None
        if not np.isfinite(inverse).all():
            raise ValueError(
                f"{what} correction inv(gain) overflows a double (the gain is nearly singular); "
                "calibrate again"
            )
        out.append((name, inverse, bias))
    return out


def exact(x: float) -> str:
    """The shortest text that reads back as the same double (``1.0``, ``1e+30``).

    Always has a decimal point or an exponent, so no target reads it as an integer.
    """
    return repr(float(x))


def comment_header(cal: Calibration, marker: str) -> list[str]:
    """The title and :func:`provenance` lines as comments starting with ``marker``."""
    return [
        f"{marker} {text}" for text in ["Sensor calibration written by fieldcal.", *provenance(cal)]
    ]


def provenance(cal: Calibration) -> list[str]:
    """Lines naming the writer, the method, the calibrated units and any folded axis map."""
    lines = [f"fieldcal {cal.version}, method {cal.method}, created {cal.created}"]
    units = cal.units or {}
    lines.append(
        f"calibrated units: accelerometer {units.get('accel_calibrated', '?')}, "
        f"magnetometer {units.get('mag_calibrated', '?')}"
        + (f", gyroscope {units.get('gyro_calibrated', 'rad/s')}" if cal.gyro is not None else "")
    )
    if cal.options.get("mag_axes"):
        lines.append(
            f"the magnetometer axis map {cal.options['mag_axes']} is folded in: apply to the raw "
            "columns as logged"
        )
    return lines
