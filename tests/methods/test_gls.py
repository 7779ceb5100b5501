"""Generalised least squares of Eq. 11-17 (fieldcal.methods.gls): exact recovery from
noise-free poses, the weighted solution against a dense Ω, and the designs' products."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from fieldcal.methods import gls


def _rotations(n: int, seed: int) -> np.ndarray:
    return Rotation.random(n, random_state=seed).as_matrix()


def test_gls_is_the_dense_weighted_least_squares():
    rng = np.random.default_rng(1)
    n, p = 8, 4
    X = rng.normal(size=(n, 3, p))
    y = rng.normal(size=(n, 3))
    A = rng.normal(size=(3, 3))
    sigma = A @ A.T + np.eye(3)
    counts = rng.integers(5, 50, size=n).astype(float)
    beta = gls.gls(X, y, np.linalg.inv(sigma), counts)
    # the same from Ω = blockdiag(Σ/Δ_i) built densely
    omega = np.zeros((3 * n, 3 * n))
    for i in range(n):
        omega[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = sigma / counts[i]
    Xd, yd = X.reshape(3 * n, p), y.reshape(3 * n)
    W = np.linalg.inv(omega)
    dense = np.linalg.solve(Xd.T @ W @ Xd, Xd.T @ W @ yd)
    np.testing.assert_allclose(beta, dense, rtol=1e-10)


def test_bias_and_field_designs_recover_the_truth_from_exact_readings():
    R = _rotations(12, seed=2)
    K = np.array([[1.1, 0.05, 0.0], [0.02, 0.9, 0.02], [0.0, 0.03, 1.0]])
    b = np.array([0.3, -0.2, 0.1])
    g_z, h_x, h_z = -1.0, 0.5, 0.8
    accel = g_z * (R[:, :, 2] @ K.T) + b  # K R_i (0, 0, g_z) + b
    mag = (h_x * R[:, :, 0] + h_z * R[:, :, 2]) @ K.T + b
    w, counts = np.eye(3), np.full(12, 10.0)
    np.testing.assert_allclose(
        gls.gls(gls.accel_bias_field_design(K, R), accel, w, counts), [g_z, *b], atol=1e-12
    )
    np.testing.assert_allclose(
        gls.gls(gls.mag_bias_field_design(K, R), mag, w, counts), [h_x, h_z, *b], atol=1e-12
    )


def test_gain_designs_reproduce_the_products():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(5, 3))
    K = rng.normal(size=(3, 3))
    S = K + K.T
    beta_s = S[[0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]]
    np.testing.assert_allclose(gls.accel_gain_design(v) @ beta_s, v @ S.T, atol=1e-12)
    np.testing.assert_array_equal(gls.symmetric_from_vector(beta_s), S)
    np.testing.assert_allclose(gls.mag_gain_design(v) @ K.ravel(), v @ K.T, atol=1e-12)
