"""The noise a user gives (fieldcal.stats.noise_models): standard deviations and covariances,
pose-level noise, and Eq. 7's Wishart standard errors against a Monte Carlo of the estimate."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.stats.noise_models import (
    noise_covariance,
    per_sensor,
    pose_noise_value,
    wishart_std,
)


def test_noise_covariance_forms():
    np.testing.assert_array_equal(noise_covariance(0.5, "accel"), 0.25 * np.eye(3))
    np.testing.assert_array_equal(noise_covariance([1, 2, 3], "mag"), np.diag([1.0, 4.0, 9.0]))
    C = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 1.0]])
    skew = C + np.array([[0, 1e-3, 0], [-1e-3, 0, 0], [0, 0, 0]])
    np.testing.assert_allclose(noise_covariance(skew, "mag"), C)  # the symmetric part


@pytest.mark.parametrize(
    ("value", "words"),
    [
        ("0.1", "must be a number or an array"),
        (True, "must be a number or an array"),
        (0.0, "finite and positive"),
        ([1.0, -1.0, 1.0], "finite and positive"),
        (1e200, "too large to square"),
        (np.ones((2, 2)), "got shape (2, 2)"),
        (np.diag([1.0, 1.0, -1.0]), "positive definite"),
    ],
)
def test_bad_noise_is_refused_naming_the_sensor(value, words):
    with pytest.raises(ValueError, match="noise for accel") as info:
        noise_covariance(value, "accel")
    assert words in str(info.value)


def test_pose_noise_values():
    assert pose_noise_value("auto", "mag") is None and pose_noise_value(None, "mag") is None
    assert pose_noise_value("none", "mag") == 0.0
    assert pose_noise_value(0.3, "mag") == pytest.approx(0.09)
    for bad in ("loud", True, -1.0, float("nan"), [1.0]):
        with pytest.raises(ValueError, match="pose_noise for mag"):
            pose_noise_value(bad, "mag")


def test_per_sensor():
    assert per_sensor(1.0, "noise") == {"accel": 1.0, "mag": 1.0}
    assert per_sensor({"mag": 2.0}, "noise") == {"accel": None, "mag": 2.0}
    with pytest.raises(
        ValueError, match=r"noise keys must be 'accel' and/or 'mag', got \['gyro'\]"
    ):
        per_sensor({"gyro": 1.0}, "noise")


def test_wishart_std_matches_a_monte_carlo_of_the_sample_covariance():
    rng = np.random.default_rng(7)
    A = rng.normal(size=(3, 3))
    sigma = A @ A.T + np.eye(3)
    n, trials = 41, 4000
    x = rng.multivariate_normal(np.zeros(3), sigma, size=(trials, n))
    x -= x.mean(axis=1, keepdims=True)
    estimates = np.einsum("tni,tnj->tij", x, x) / (n - 1)
    spread = estimates.std(axis=0)
    # 4000 trials: the spread's own relative error is about 1/sqrt(2·4000) ≈ 1.1 %
    np.testing.assert_allclose(wishart_std(sigma, n - 1), spread, rtol=0.06)
    assert np.all(np.isfinite(wishart_std(sigma, 0)))
