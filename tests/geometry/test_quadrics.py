"""Quadric fits (fieldcal.geometry.quadrics): exact recovery of a known ellipsoid from points on
it by both fits, invariance to weights of equal size, Eq. 13's factor against ``LᵀL = M``, the
radii of a known shape."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fieldcal.geometry import quadrics

CENTER = np.array([0.3, -0.2, 0.5])
RADII = np.array([2.0, 1.5, 1.2])


def _ellipsoid_points(n: int, seed: int, noise: float = 0.0):
    """Points on ``(x − c)ᵀ M (x − c) = 1``, M = Q diag(1/r²) Qᵀ."""
    rng = np.random.default_rng(seed)
    Q = Rotation.random(random_state=seed).as_matrix()
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    x = (u * RADII) @ Q.T + CENTER
    M = Q @ np.diag(1 / RADII**2) @ Q.T
    return x + noise * rng.normal(size=x.shape), M


@pytest.mark.parametrize("fit", [quadrics.algebraic_fit, quadrics.li_griffiths_fit])
def test_points_on_an_ellipsoid_give_it_back(fit):
    x, M = _ellipsoid_points(60, seed=1)
    q = fit(x)
    assert q.is_ellipsoid
    np.testing.assert_allclose(q.center, CENTER, atol=1e-9)
    np.testing.assert_allclose(q.shape, M, atol=1e-9)
    np.testing.assert_allclose(
        np.sort(quadrics.ellipsoid_radii(q.shape)), np.sort(RADII), rtol=1e-9
    )
    residual = np.einsum("ni,ij,nj->n", x - q.center, q.shape, x - q.center) - 1
    assert np.abs(residual).max() < 1e-9


def test_equal_weights_change_nothing_and_a_zero_weight_drops_a_point():
    x, _ = _ellipsoid_points(40, seed=2, noise=0.01)
    plain = quadrics.algebraic_fit(x)
    weighted = quadrics.algebraic_fit(x, np.full(40, 3.0))
    np.testing.assert_allclose(weighted.shape, plain.shape, rtol=1e-9)
    outlier = np.vstack([x, [[50.0, 50.0, 50.0]]])
    dropped = quadrics.algebraic_fit(outlier, np.r_[np.ones(40), 0.0])
    np.testing.assert_allclose(dropped.center, plain.center, atol=1e-9)


def test_too_few_points_are_refused():
    x, _ = _ellipsoid_points(quadrics.MIN_POINTS - 1, seed=3)
    with pytest.raises(ValueError):
        quadrics.algebraic_fit(x)


def test_reverse_triangular_factor():
    rng = np.random.default_rng(4)
    A = rng.normal(size=(5, 3, 3))
    M = A @ np.swapaxes(A, 1, 2) + np.eye(3)
    L = quadrics.reverse_triangular_factor(M)
    np.testing.assert_allclose(np.swapaxes(L, 1, 2) @ L, M, atol=1e-12)
    assert np.all(np.triu(L, 1) == 0) and np.all(np.diagonal(L, axis1=1, axis2=2) > 0)
    assert np.isnan(quadrics.reverse_triangular_factor(-np.eye(3))).any()


def test_radii_of_a_known_shape_longest_first_and_nan_when_not_an_ellipsoid():
    np.testing.assert_allclose(quadrics.ellipsoid_radii(np.diag([1 / 4, 1, 1 / 9])), [3, 2, 1])
    assert np.isnan(quadrics.ellipsoid_radii(np.diag([1.0, 1.0, -1.0]))).sum() == 1
    hyperboloid = quadrics.Quadric(np.zeros(10), np.zeros(3), 1.0, np.diag([1.0, 1.0, -1.0]))
    assert not hyperboloid.is_ellipsoid
