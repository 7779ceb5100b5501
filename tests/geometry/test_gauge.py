"""fieldcal's gauge (fieldcal.geometry.gauge): any parameter set re-expressed with the same
predicted readings, unit fields in the stated world frame, the body-frame gain symmetric
positive definite, and a canonical set left as it is."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fieldcal.geometry.gauge import canonical_gauge


def _random_set(seed: int):
    rng = np.random.default_rng(seed)
    R = Rotation.random(6, random_state=seed).as_matrix()
    Ka = np.eye(3) + 0.1 * rng.normal(size=(3, 3))
    Km = 40 * (np.eye(3) + 0.1 * rng.normal(size=(3, 3)))
    g = 9.8 * Rotation.random(random_state=seed + 100).apply([0.0, 0.0, -1.0])
    h = 0.5 * rng.normal(size=3)
    return R, Ka, Km, g, h


def _predictions(R, K, f):
    """K R_i f for every pose."""
    return np.einsum("ij,njk,k->ni", K, R, f)


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("body_frame", ["accel", "mag"])
def test_predictions_are_unchanged_in_the_stated_frames(seed, body_frame):
    R, Ka, Km, g, h = _random_set(seed)
    R2, Ka2, Km2, g2, h2 = canonical_gauge(R, Ka, Km, g, h, body_frame)
    np.testing.assert_allclose(_predictions(R2, Ka2, g2), _predictions(R, Ka, g), atol=1e-10)
    np.testing.assert_allclose(_predictions(R2, Km2, h2), _predictions(R, Km, h), atol=1e-9)
    np.testing.assert_allclose(g2, [0.0, 0.0, -1.0], atol=1e-15)
    assert np.linalg.norm(h2) == pytest.approx(1.0) and abs(h2[1]) < 1e-12 and h2[0] > 0
    K = Ka2 if body_frame == "accel" else Km2
    np.testing.assert_allclose(K, K.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(0.5 * (K + K.T)) > 0)
    np.testing.assert_allclose(
        R2 @ np.swapaxes(R2, 1, 2), np.broadcast_to(np.eye(3), R2.shape), atol=1e-12
    )


def test_a_canonical_set_is_left_as_it_is():
    R, Ka, Km, g, h = _random_set(1)
    once = canonical_gauge(R, Ka, Km, g, h)
    twice = canonical_gauge(*once)
    for a, b in zip(once, twice, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)


def test_one_sensor_alone():
    R, Ka, _, g, _ = _random_set(2)
    R2, Ka2, Km2, g2, h2 = canonical_gauge(R, Ka, None, g, None)
    assert Km2 is None and h2 is None
    np.testing.assert_allclose(_predictions(R2, Ka2, g2), _predictions(R, Ka, g), atol=1e-10)


def test_refusals():
    R, Ka, Km, g, h = _random_set(3)
    with pytest.raises(ValueError, match="given together"):
        canonical_gauge(R, Ka, Km, None, h)
    mirrored = Ka @ np.diag([1.0, 1.0, -1.0])
    with pytest.raises(ValueError, match="accel gain has a negative determinant"):
        canonical_gauge(R, mirrored if np.linalg.det(Ka) > 0 else Ka, Km, g, h)
