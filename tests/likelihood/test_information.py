"""From information to error bars (fieldcal.likelihood.information): the Jacobi-scaled inverse
against an independent inverse on badly scaled parameters, the pseudo-inverse of an information
singular in one direction, and the sandwich's known answers."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.likelihood.information import jacobi_scaled, sandwich, scaled_inverse


def _information(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    J = rng.standard_normal((40, 6))
    units = np.array([1e-6, 1e-3, 1.0, 1e3, 1e6, 10.0])  # parameters in units far apart
    J = J / units
    return J.T @ J


def test_the_scaled_inverse_is_the_inverse_however_the_units_differ():
    S = _information(0)
    C = scaled_inverse(S)
    np.testing.assert_array_equal(C, C.T)
    Sn, scale = jacobi_scaled(S)
    np.testing.assert_allclose(np.diag(Sn), 1.0)
    np.testing.assert_allclose(Sn * scale, S)
    # in units where every parameter is of size 1, C is S's inverse (an independent one)
    np.testing.assert_allclose((C * scale) @ Sn, np.eye(6), atol=1e-10)
    np.testing.assert_allclose(C * scale, np.linalg.inv(Sn), rtol=1e-9, atol=1e-12)


def test_a_singular_information_raises_or_has_a_pseudo_inverse():
    S = _information(1)
    v = np.linalg.eigh(S)[1][:, 0]
    S = S - (v @ S @ v) * np.outer(v, v)  # no information along v
    P = scaled_inverse(S, pseudo=True)
    np.testing.assert_allclose(S @ P @ S, S, rtol=1e-6, atol=1e-6 * np.abs(S).max())
    with pytest.raises(np.linalg.LinAlgError):
        scaled_inverse(np.zeros((3, 3)))


def test_the_sandwich_is_the_inverse_when_the_scores_covariance_is_the_information():
    S = _information(2)
    C = scaled_inverse(S)
    np.testing.assert_allclose(sandwich(C, S), C, rtol=1e-8, atol=1e-12 * np.abs(C).max())
    np.testing.assert_allclose(
        sandwich(C, 4.0 * S), 4.0 * C, rtol=1e-8, atol=1e-12 * np.abs(C).max()
    )
