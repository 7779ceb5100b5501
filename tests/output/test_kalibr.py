"""The ``kalibr``/``openvins`` exports (fieldcal.output.exports.kalibr): the noise densities a
calibration determines, as known answers from its per-sample covariance; the ``imu.yaml``
itself is refused without random walks."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from _known import ACCEL_GAIN, GYRO_GAIN, known_calibration

from fieldcal.errors import InputError
from fieldcal.output.exports import kalibr


def test_densities_are_the_calibrated_sample_noise_over_root_rate():
    cal = known_calibration(gyro=True, rate=400.0)
    rate, accel, gyro = kalibr.kalibr_noise(cal)
    assert rate == 400.0
    # noise_cov = sigma^2 I per raw sample: calibrated sigma_i = sigma |row i of inv(gain)|
    A, Gi = np.linalg.inv(ACCEL_GAIN), np.linalg.inv(GYRO_GAIN)
    np.testing.assert_allclose(accel, 0.02 * np.linalg.norm(A, axis=1) / math.sqrt(400), rtol=1e-12)
    np.testing.assert_allclose(gyro, 0.003 * np.abs(np.diag(Gi)) / math.sqrt(400), rtol=1e-12)
    noise = kalibr.imu_noise(cal)
    assert noise.accel_density == accel.max() and noise.gyro_density == gyro.max()
    assert noise.accel_walk is None and noise.gyro_walk is None


def test_g_units_are_converted_to_metres_per_second_squared():
    cal = known_calibration(gyro=True, rate=100.0)
    in_g = cal.with_field_magnitudes(gravity=1.0)  # the same readings calibrated in g
    np.testing.assert_allclose(
        kalibr.kalibr_noise(in_g)[1], kalibr.kalibr_noise(cal)[1], rtol=1e-12
    )


@pytest.mark.parametrize("write", [kalibr.write, kalibr.write_openvins])
def test_the_yaml_is_refused_naming_fieldcal_noise(write):
    with pytest.raises(InputError, match="fieldcal noise") as info:
        write(known_calibration(gyro=True, rate=100.0))
    assert "\n" not in str(info.value)


def test_missing_gyroscope_or_rate_is_refused():
    with pytest.raises(InputError, match="no gyroscope"):
        kalibr.kalibr_noise(known_calibration(rate=100.0))
    for rate in (None, True, 0.0, math.inf):
        cal = dataclasses.replace(known_calibration(gyro=True), options={"rate": rate})
        with pytest.raises(InputError, match="no sample rate"):
            kalibr.kalibr_noise(cal)
