"""A calibration built by hand from round numbers, for known-answer tests of what reads one
(the exports, the trust checks): every value a test expects is computed from these numbers.

Units as an autopilot's drivers deliver them: the accelerometer in m/s² (|g| = 9.80665), the
magnetometer in milligauss calibrated to µT (|h| = 48.5 µT, gain ≈ 10 mG/µT).
"""

from __future__ import annotations

import numpy as np

from fieldcal.calibration import Calibration, SensorCalibration

G = 9.80665
FIELD_UT = 48.5
DIP_DEG = 60.0

#: Symmetric (no rotation between the two sensors): an autopilot holds it exactly.
ACCEL_GAIN = np.array([[1.02, 0.01, -0.005], [0.01, 0.98, 0.002], [-0.005, 0.002, 1.01]])
ACCEL_BIAS = np.array([0.3, -0.2, 0.1])
MAG_GAIN = 10.0 * np.array([[1.1, 0.05, 0.0], [0.05, 0.9, 0.02], [0.0, 0.02, 1.0]])
MAG_BIAS = np.array([100.0, -50.0, 30.0])
GYRO_GAIN = np.diag([1.01, 0.99, 1.0])
GYRO_BIAS = np.array([0.01, -0.02, 0.005])


def known_calibration(*, gyro: bool = False, rate: float | None = None) -> Calibration:
    """The calibration of this module's numbers, with three poses, optionally a gyroscope
    and a sample rate (``options["rate"]``)."""
    dip = np.radians(DIP_DEG)

    def sensor(gain: np.ndarray, bias: np.ndarray, sigma: float) -> SensorCalibration:
        return SensorCalibration(gain=gain, bias=bias, noise_cov=sigma**2 * np.eye(3))

    rotations = np.stack([np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0])])
    return Calibration(
        accel=sensor(ACCEL_GAIN, ACCEL_BIAS, 0.02),
        mag=sensor(MAG_GAIN, MAG_BIAS, 2.0),
        gravity=np.array([0.0, 0.0, -G]),
        magnetic=FIELD_UT * np.array([np.cos(dip), 0.0, np.sin(dip)]),
        rotations=rotations,
        method="truth",
        options={} if rate is None else {"rate": rate},
        gyro=sensor(GYRO_GAIN, GYRO_BIAS, 0.003) if gyro else None,
    )
