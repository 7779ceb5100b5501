"""The ``kalibr`` and ``openvins`` exports: the ``imu.yaml`` of Kalibr and OpenVINS from a
calibration, written by :func:`fieldcal.noise.imu_yaml`, the one writer ``fieldcal noise`` uses.

Kalibr's IMU noise model (its wiki, "IMU Noise Model") takes continuous-time noise densities:
a white noise of standard deviation ``σ`` per sample at ``update_rate`` Hz has the density
``σ · sqrt(1 / update_rate)``. fieldcal's ``noise_cov`` is the covariance of one raw sample;
in calibrated units it is ``inv(gain) Σ inv(gain)ᵀ`` (times the unit factor squared), and each
key gets the **largest** axis (the conservative choice, as ``fieldcal noise``).

What a calibration cannot give, this export does not invent and does not write commented out:
the random walks need a long still recording. Without them the export is refused in one line
naming ``fieldcal noise``, which measures all four figures; so are a calibration without a
gyroscope or without a sample rate. :func:`kalibr_noise` gives the densities a calibration
does determine.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ...calibration import Calibration
from ...errors import InputError
from ...imu_yaml import ImuNoise, imu_yaml
from .autopilot import accel_factor
from .common import comment_header, corrections

__all__ = [
    "CONTENT",
    "FORMULA",
    "OPENVINS_CONTENT",
    "imu_noise",
    "kalibr_noise",
    "write",
    "write_openvins",
]

FORMULA = "noise_density = sigma_sample * sqrt(1 / update_rate)"
CONTENT = (
    "Kalibr `imu.yaml`: the four noise figures, `rostopic`, `update_rate`; refused from a "
    "calibration (no random walks): `fieldcal noise LOG --export kalibr` writes it"
)
OPENVINS_CONTENT = (
    "OpenVINS `kalibr_imu_chain.yaml` (`%YAML:1.0`, the `imu0` block); refused from a "
    "calibration (no random walks): `fieldcal noise` writes it"
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


def imu_noise(cal: Calibration) -> ImuNoise:
    """The figures of an ``imu.yaml`` a calibration gives: the densities and the rate; the
    random walks unknown (``None``, with why).

    Raises
    ------
    InputError
        See :func:`kalibr_noise`.
    """
    rate, accel, gyro = kalibr_noise(cal)

    def axes(v: Array) -> str:
        return ", ".join(f"{x:.6g}" for x in v)

    unknown = "a calibration does not measure the bias random walks"
    return ImuNoise(
        rate=rate,
        accel_density=float(accel.max()),
        accel_walk=None,
        gyro_density=float(gyro.max()),
        gyro_walk=None,
        notes={
            "accelerometer_noise_density": f"[m/s^2/sqrt(Hz)] largest axis; x,y,z {axes(accel)}",
            "gyroscope_noise_density": f"[rad/s/sqrt(Hz)] largest axis; x,y,z {axes(gyro)}",
            "update_rate": "[Hz] the calibration's options.rate",
        },
        why={"accelerometer_random_walk": unknown, "gyroscope_random_walk": unknown},
    )


def write(cal: Calibration) -> str:
    """Kalibr's ``imu.yaml`` (refused: a calibration has no random walks).

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    str

    Raises
    ------
    InputError
        See :func:`kalibr_noise`; and the random walks, which no calibration gives, in one line
        naming ``fieldcal noise``.
    """
    return imu_yaml(imu_noise(cal), "kalibr", header=_header(cal))


def write_openvins(cal: Calibration) -> str:
    """OpenVINS' ``kalibr_imu_chain.yaml`` (refused as :func:`write`).

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    str

    Raises
    ------
    InputError
        As :func:`write`.
    """
    return imu_yaml(imu_noise(cal), "openvins", header=_header(cal))


def _header(cal: Calibration) -> list[str]:
    lines = [text[2:] for text in comment_header(cal, "#")]
    return [*lines, f"{FORMULA}, sigma_sample from the calibration's per-sample noise covariance"]
