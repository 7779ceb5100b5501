"""The gyroscope model's SO(3) pieces (fieldcal.gyro.model): J_r and its inverse against
their defining properties, small angles on both sides of the series' switch, the same J_r as the
continuous estimator's, tangent bases. (The segment model's residuals and Jacobians:
tests/gyro/test_passes.py.)"""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.geometry.rotations import exp_so3, log_so3
from fieldcal.gyro.model import right_jacobian, right_jacobian_inv, tangent_basis
from fieldcal.methods.continuous import preintegration


def _phis(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(8, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    # angles on both sides of the series switch (1e-3) and up to 3 rad
    angles = np.array([0.0, 1e-6, 9.9e-4, 1.01e-3, 0.1, 1.0, 2.0, 3.0])
    return directions * angles[:, None]


def test_right_jacobian_and_its_inverse():
    phi = _phis(1)
    J, Jinv = right_jacobian(phi), right_jacobian_inv(phi)
    np.testing.assert_allclose(J @ Jinv, np.broadcast_to(np.eye(3), J.shape), atol=1e-10)
    # the continuous estimator's J_r is the same function (written separately)
    np.testing.assert_allclose(J, preintegration.right_jacobian(phi), atol=1e-12)


@pytest.mark.parametrize("k", range(1, 8))
def test_log_of_a_perturbed_turn(k):
    phi = _phis(2)[k]
    eps = 1e-7 * np.random.default_rng(k).normal(size=3)
    # log(exp(φ) exp(ε)) ≈ φ + J_r(φ)⁻¹ ε, and exp(φ + δ) ≈ exp(φ) exp(J_r(φ) δ)
    np.testing.assert_allclose(
        log_so3(exp_so3(phi) @ exp_so3(eps)), phi + right_jacobian_inv(phi) @ eps, atol=1e-12
    )
    turn = log_so3(exp_so3(phi).T @ exp_so3(phi + eps))
    np.testing.assert_allclose(turn, right_jacobian(phi) @ eps, atol=1e-12)


def test_tangent_bases_are_orthonormal_and_orthogonal_to_u():
    u = np.random.default_rng(3).normal(size=(50, 3))
    u = np.vstack([u, np.eye(3), -np.eye(3)])
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    B = tangent_basis(u)
    assert B.shape == (56, 3, 2)
    np.testing.assert_allclose(
        np.swapaxes(B, 1, 2) @ B, np.broadcast_to(np.eye(2), (56, 2, 2)), atol=1e-12
    )
    np.testing.assert_allclose(np.einsum("ni,nij->nj", u, B), 0.0, atol=1e-12)
    # (u, e1, e2) is right-handed
    det = np.linalg.det(np.concatenate([u[:, :, None], B], axis=2))
    np.testing.assert_allclose(det, 1.0, atol=1e-12)
