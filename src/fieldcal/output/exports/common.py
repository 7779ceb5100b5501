"""What every export writes: the correction matrices, the provenance and verdict lines, exact
numbers."""

from __future__ import annotations

from typing import cast

import numpy as np
from numpy.typing import NDArray

from ...calibration import GYRO, SENSORS, Calibration, SensorCalibration
from ...thermal import TemperatureModel

__all__ = [
    "MAX_TEMPERATURE_ORDER",
    "NAMES",
    "TEMPERATURE_FORMULA",
    "comment_header",
    "corrections",
    "cubic",
    "exact",
    "provenance",
    "temperature_terms",
    "verdict_line",
]

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


#: The highest order an export holds (PX4's cubic ``TC_*`` polynomials; fieldcal fits at most
#: this, :data:`fieldcal.likelihood.temperature.MAX_ORDER`).
MAX_TEMPERATURE_ORDER = 3
#: The bias's temperature terms as every export states them (``docs/methods/temperature.md``).
TEMPERATURE_FORMULA = (
    "bias(T) = bias + c1*d + c2*d^2 + c3*d^3, d = min(max(T, T_min), T_max) - T_ref (T in deg C)"
)


def temperature_terms(cal: Calibration) -> list[tuple[str, TemperatureModel]]:
    """``(sensor, model)`` for each sensor whose bias has fitted temperature terms (order 1 or
    more), in the order of :func:`corrections`; empty for a calibration without any, whose
    exports are then exactly those of a calibration made without a temperature column.

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    list of (str, TemperatureModel)
    """
    out: list[tuple[str, TemperatureModel]] = []
    for name in (*SENSORS, GYRO):
        sensor: SensorCalibration | None = getattr(cal, name)
        model = None if sensor is None else sensor.temperature
        if model is not None and model.order > 0:
            if model.order > MAX_TEMPERATURE_ORDER:
                raise ValueError(
                    f"cannot export: the {NAMES[name]}'s temperature terms are of order "
                    f"{model.order}; the exports hold at most {MAX_TEMPERATURE_ORDER} (cubic)"
                )
            out.append((name, model))
    return out


def cubic(model: TemperatureModel) -> Array:
    """(3, 3): the coefficients ``c1, c2, c3`` per row (raw units per K^k), zeros beyond the
    model's order."""
    out = np.zeros((MAX_TEMPERATURE_ORDER, 3))
    out[: model.order] = model.coefficients
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


def verdict_line(cal: Calibration) -> str:
    """The verdict as one line: ``verdict: WARN (codes: accuracy, untested)``.

    The codes are what scripts read (``Reason.code``); a reason without a code (an older
    verdict, a plain string) is named by its first words. A calibration without a verdict
    says so, so every export carries the line.

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    str
        One line, no newline, no comment marker.
    """
    verdict = cal.verdict
    if verdict is None:
        return "verdict: none (this calibration was not judged)"
    codes = []
    for reason in verdict.reasons:
        code = str(getattr(reason, "code", reason))
        code = " ".join(code.split())  # a plain-text reason: one line
        codes.append(code if len(code) <= 60 else code[:57] + "...")
    listed = f" (codes: {', '.join(codes)})" if codes else " (no reasons)"
    return f"verdict: {str(verdict.level).upper()}{listed}"


def provenance(cal: Calibration) -> list[str]:
    """Lines naming the writer, the method, the verdict, the calibrated units and any folded
    axis map."""
    lines = [f"fieldcal {cal.version}, method {cal.method}, created {cal.created}"]
    lines.append(verdict_line(cal))
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
