"""The ``kalibr`` export: the ``imu.yaml`` of Kalibr and OpenVINS from a calibration.

Kalibr's IMU noise model (its wiki, "IMU Noise Model") takes continuous-time noise densities:
a white noise of standard deviation ``σ`` per sample at ``update_rate`` Hz has the density
``σ · sqrt(1 / update_rate)``. fieldcal's ``noise_cov`` is the covariance of one raw sample;
in calibrated units it is ``inv(gain) Σ inv(gain)ᵀ`` (times the unit factor squared), and each
key gets the **largest** axis (the conservative choice, as ``fieldcal noise``; every axis is in
a comment).

What a calibration cannot give, this export does not invent:

- the gyroscope: without ``cal.gyro`` there is no gyroscope density: refused;
- the sample rate: read from ``cal.options["rate"]``; without it: refused;
- the random walks (bias instability needs a long still recording, ``fieldcal noise``): the
  two ``*_random_walk`` keys are written **commented out** and marked UNKNOWN, so Kalibr stops
  on the missing key instead of running on a guess. ``fieldcal noise LOG --export kalibr``
  measures all four figures.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ...calibration import Calibration
from ...errors import InputError
from .autopilot import accel_factor
from .common import comment_header, corrections

__all__ = ["CONTENT", "FORMULA", "kalibr_noise", "write"]

FORMULA = "noise_density = sigma_sample * sqrt(1 / update_rate)"
CONTENT = (
    "Kalibr/OpenVINS `imu.yaml`: `accelerometer_noise_density` (m/s²/√Hz), "
    "`gyroscope_noise_density` (rad/s/√Hz), `update_rate`; the random walks marked UNKNOWN"
)

_FIX = "fieldcal noise LOG --export kalibr measures the figures from a still recording"

Array = NDArray[np.float64]


def kalibr_noise(cal: Calibration) -> tuple[float, Array, Array]:
    """``(rate, accel densities, gyro densities)``: per axis, in m/s²/√Hz and rad/s/√Hz.

    Parameters
    ----------
    cal : Calibration
        With a gyroscope and ``options["rate"]`` (Hz).

    Returns
    -------
    tuple of (float, (3,) array, (3,) array)

    Raises
    ------
    InputError
        No gyroscope, no accelerometer, no rate, or accelerometer units that are neither g nor
        m/s².
    """
    inverses = {name: M for name, M, _ in corrections(cal)}
    if cal.gyro is None or cal.accel is None:
        missing = "gyroscope" if cal.gyro is None else "accelerometer"
        raise InputError(f"cannot export kalibr: the calibration has no {missing}; {_FIX}")
    rate = cal.options.get("rate")
    if isinstance(rate, bool) or not isinstance(rate, int | float) or not 0 < rate < math.inf:
        raise InputError(f"cannot export kalibr: the calibration records no sample rate; {_FIX}")

    def sigma(name: str, cov: Array, factor: float) -> Array:
        M = inverses[name]
        return factor * np.sqrt(np.diag(M @ cov @ M.T))

    scale = math.sqrt(1.0 / float(rate))
    accel = sigma("accel", np.asarray(cal.accel.noise_cov, dtype=float), accel_factor(cal))
    gyro = sigma("gyro", np.asarray(cal.gyro.noise_cov, dtype=float), 1.0)
    return float(rate), accel * scale, gyro * scale


def write(cal: Calibration) -> str:
    """Kalibr's ``imu.yaml``; the random walks commented out as UNKNOWN.

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    str

    Raises
    ------
    InputError
        See :func:`kalibr_noise`.
    """
    rate, accel, gyro = kalibr_noise(cal)

    def axes(v: Array) -> str:
        return ", ".join(f"{x:.6g}" for x in v)

    lines = comment_header(cal, "#")
    lines += [
        f"# Kalibr / OpenVINS imu.yaml: {FORMULA},",
        "# sigma_sample from the calibration's per-sample noise covariance in calibrated units;",
        "# each value is the LARGEST of the three axes (x, y, z in the comment).",
        "rostopic: /imu0  # edit: your IMU topic",
        f"update_rate: {rate!r}  # Hz, the calibration's options.rate",
        f"accelerometer_noise_density: {float(accel.max())!r}"
        f"  # m/s^2/sqrt(Hz); axes {axes(accel)}",
        f"gyroscope_noise_density: {float(gyro.max())!r}  # rad/s/sqrt(Hz); axes {axes(gyro)}",
        "# UNKNOWN: a calibration does not measure the random walks, so they are not written and",
        "# Kalibr will stop on the missing keys. Fill them in: " + _FIX + ".",
        "# accelerometer_random_walk: UNKNOWN  # m/s^3/sqrt(Hz)",
        "# gyroscope_random_walk: UNKNOWN  # rad/s^2/sqrt(Hz)",
    ]
    return "\n".join(lines) + "\n"
