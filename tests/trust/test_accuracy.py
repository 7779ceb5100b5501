"""Predicted accuracy (fieldcal.trust.accuracy): the norm and direction errors from the moments
of the orientations, against the covariance of every corrected reading written out."""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.trust import accuracy


def _plain_norm_and_direction(cal: fieldcal.Calibration, sensor: str) -> tuple[float, float]:
    """Per orientation: ``C = K⁻¹ (G P Gᵀ + q² I) K⁻ᵀ / |f|²``, its radial part and trace."""
    sc = cal.sensor(sensor)
    ref = float(np.linalg.norm(cal.reference(sensor)))
    v = accuracy._SPHERE
    u = v * ref
    G = np.zeros((len(u), 3, 12))
    for j in range(3):
        G[:, j, 3 * j : 3 * j + 3] = u
        G[:, j, 9 + j] = 1.0
    C = G @ accuracy._param_block(cal.covariance, sensor) @ G.transpose(0, 2, 1)
    C = C + sc.pose_noise_std**2 * np.eye(3)
    Kinv = np.linalg.inv(sc.gain)
    C = Kinv @ C @ Kinv.T / ref**2
    radial = np.einsum("ni,nij,nj->n", v, C, v)
    perp = np.trace(C, axis1=1, axis2=2) - radial
    return float(np.sqrt(radial.mean())), float(np.degrees(np.sqrt(max(perp.mean(), 0.0))))


@pytest.mark.parametrize(("preset", "seed"), [("paper", 0), ("paper", 4), ("hard", 1)])
def test_norm_and_direction_from_moments_equal_the_per_orientation_covariances(preset, seed):
    s = fieldcal.simulate(preset, seed=seed)
    cal = fieldcal.calibrate(s.accel, s.mag, field_strength=48.0, gravity=9.81)
    for sensor in ("accel", "mag"):
        fast = accuracy._norm_and_direction(cal, sensor)
        # the same sums in another order: rounding only
        assert fast == pytest.approx(_plain_norm_and_direction(cal, sensor), rel=1e-12)
    # the magnetometer's direction is not asked for: its norm alone, the same number
    mag_norm, unused = accuracy._norm_and_direction(cal, "mag", direction=False)
    assert unused == 0.0
    assert mag_norm == pytest.approx(_plain_norm_and_direction(cal, "mag")[0], rel=1e-12)


def test_the_orientations_moments_are_those_of_the_lattice():
    v = accuracy._SPHERE
    s1, s2, s3, s4 = accuracy._moments(v)
    np.testing.assert_allclose(s2, np.eye(3) / 3, atol=0.02)  # nearly isotropic
    assert np.trace(s2) == pytest.approx(1.0, rel=1e-12)  # unit vectors
    # a fourth moment contracted twice is the mean of |v|⁴ = 1
    assert np.einsum("iijj->", s4) == pytest.approx(1.0, rel=1e-12)
    np.testing.assert_allclose(np.einsum("ijj->i", s3), s1, atol=1e-15)  # |v|² = 1 inside
