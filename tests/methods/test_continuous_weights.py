"""Noise levels of the continuous fit (fieldcal.methods.continuous.weights): per-stretch
variances as known answers (a partial last stretch, the floor), and the gyroscope's white-noise
variance recovered through a smooth motion from the second differences."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.methods.continuous.weights import gyro_rate_variance, stretch_variance


def test_stretch_variances_are_the_mean_squares_per_stretch():
    residual = np.zeros((7, 3))
    residual[:3] = 2.0  # stretch 0: mean square per axis 4
    residual[3:6] = [[3.0, 0.0, 0.0]] * 3  # stretch 1: (9 + 0 + 0) / 3 = 3
    residual[6] = 0.0  # a partial last stretch of one sample: the floor
    per_sample, per = stretch_variance(residual, length=3, floor=0.5)
    np.testing.assert_array_equal(per, [4.0, 3.0, 0.5])
    np.testing.assert_array_equal(per_sample, [4, 4, 4, 3, 3, 3, 0.5])
    _, one = stretch_variance(residual, length=0, floor=0.0)  # a length under 1: one sample
    np.testing.assert_array_equal(one, [4, 4, 4, 3, 3, 3, 0])


@pytest.mark.parametrize("sigma", [1e-3, 5e-3])
def test_the_gyroscopes_white_noise_is_found_through_the_motion(sigma):
    rng = np.random.default_rng(7)
    n, rate = 20_000, 100.0
    t = np.arange(n) / rate
    motion = np.column_stack([np.sin(0.5 * t), 0.3 * np.cos(0.2 * t), 0.1 * t])  # smooth, large
    gain = np.diag([1.02, 0.97, 1.0])
    raw = motion @ gain.T + sigma * rng.standard_normal((n, 3))
    found = gyro_rate_variance(raw, gain)
    expected = sigma**2 * np.mean(1 / np.diag(gain) ** 2)
    # the MAD of 20,000 second differences: a few percent
    assert found == pytest.approx(expected, rel=0.05)
    assert gyro_rate_variance(np.zeros((10, 3)), gain) == 1e-20  # never zero
