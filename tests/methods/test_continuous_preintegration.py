"""The gyroscope between epochs (fieldcal.methods.continuous.preintegration): Eq. C3-C5's
residuals zero for rotations that follow the calibrated rates, their Jacobians against central
differences, and J_r against its defining property."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.geometry.rotations import exp_so3, log_so3
from fieldcal.methods.continuous.preintegration import (
    gyro_factors,
    right_jacobian,
    thermal_factors,
)

GAIN = np.array([[1.02, 0.01, 0.0], [-0.01, 0.98, 0.005], [0.0, 0.003, 1.01]])
BIAS = np.array([0.02, -0.01, 0.005])


def _log(n: int = 40, rate: float = 100.0, seed: int = 1):
    """Rotations turned by a constant body rate ω (dR/dt = −[ω]× R) and the raw readings
    ``K ω + b`` of it: the calibrated turn is exact."""
    rng = np.random.default_rng(seed)
    omega = rng.normal(scale=1.0, size=3)
    t = np.arange(n) / rate
    R0 = exp_so3(rng.normal(size=3))
    R = np.stack([exp_so3(-omega * tk) @ R0 for tk in t])
    raw = np.broadcast_to(GAIN @ omega + BIAS, (n, 3)).copy()
    return R, t, raw, omega


@pytest.mark.parametrize("hold", ["midpoint", "previous"])
def test_rotations_that_follow_the_rates_leave_no_residual(hold):
    R, t, raw, omega = _log()
    f = gyro_factors(R, t, raw, GAIN, BIAS, hold)
    assert np.abs(f.residual).max() < 1e-12
    np.testing.assert_allclose(f.rates, np.broadcast_to(omega, f.rates.shape), atol=1e-12)
    np.testing.assert_allclose(f.dt, 0.01)


def test_the_jacobians_are_the_residuals_derivatives():
    R, t, raw, _ = _log(n=6)
    # C5 holds for e small (the gyroscope's noise): at a fit, here within 1e-7 rad of it
    rng = np.random.default_rng(2)
    R = np.stack([exp_so3(1e-7 * rng.normal(size=3)) @ r for r in R])
    f = gyro_factors(R, t, raw, GAIN, BIAS)
    h = 1e-6
    params = np.concatenate([GAIN.ravel(), BIAS])
    for k in range(12):
        step = np.zeros(12)
        step[k] = h
        up, down = params + step, params - step
        e_up = -gyro_factors(R, t, raw, up[:9].reshape(3, 3), up[9:]).residual
        e_down = -gyro_factors(R, t, raw, down[:9].reshape(3, 3), down[9:]).residual
        np.testing.assert_allclose(f.params[:, :, k], (e_up - e_down) / (2 * h), atol=1e-7)
    for a in range(3):  # δ on epoch j moves e_j through "previous" and e_{j−1} by I
        d = np.zeros(3)
        d[a] = h
        moved_up = np.stack([exp_so3(d) @ r for r in R])
        moved_down = np.stack([exp_so3(-d) @ r for r in R])
        e_up = -gyro_factors(np.concatenate([moved_up[:1], R[1:]]), t, raw, GAIN, BIAS).residual
        e_down = -gyro_factors(np.concatenate([moved_down[:1], R[1:]]), t, raw, GAIN, BIAS).residual
        # (exact at e = 0; within |e| ≈ 1e-7 here)
        np.testing.assert_allclose(f.previous[0, :, a], (e_up[0] - e_down[0]) / (2 * h), atol=1e-6)


def test_right_jacobian_maps_a_step_of_phi_to_the_turn_after_it():
    rng = np.random.default_rng(3)
    for scale in (1e-6, 1e-3, 0.5, 2.0):
        phi = scale * rng.normal(size=3)
        d = 1e-7 * rng.normal(size=3)
        # Exp(φ + d) = Exp(φ) Exp(J_r(φ) d) to first order
        turn = log_so3(exp_so3(phi).T @ exp_so3(phi + d))
        np.testing.assert_allclose(turn, right_jacobian(phi) @ d, atol=1e-12)
    both = right_jacobian(np.array([[0.0, 0.0, 0.0], [0.1, 0.2, 0.3]]))
    np.testing.assert_array_equal(both[0], np.eye(3))


def test_thermal_factors_are_the_gyro_factors_of_the_raw_minus_the_drift():
    R, t, raw, _ = _log(n=8)
    temperature = np.linspace(-2.0, 3.0, 8)
    c = np.array([[1e-3, -2e-3, 5e-4], [1e-4, 0.0, -1e-4]])
    drift = (temperature[:, None] ** np.array([1, 2])) @ c
    f = thermal_factors(R, t, raw + drift, GAIN, BIAS, "midpoint", c, temperature)
    plain = gyro_factors(R, t, raw, GAIN, BIAS, "midpoint")
    np.testing.assert_allclose(f.residual, plain.residual, atol=1e-12)
    assert f.params.shape == (7, 3, 18)
    h = 1e-6
    for k in range(6):
        step = np.zeros(6)
        step[k] = h
        up = thermal_factors(
            R, t, raw + drift, GAIN, BIAS, "midpoint", c + step.reshape(2, 3), temperature
        )
        down = thermal_factors(
            R, t, raw + drift, GAIN, BIAS, "midpoint", c - step.reshape(2, 3), temperature
        )
        np.testing.assert_allclose(
            f.params[:, :, 12 + k], (down.residual - up.residual) / (2 * h), atol=1e-8
        )
    assert thermal_factors(R, t, raw, GAIN, BIAS, "midpoint", None, None).params.shape == (7, 3, 12)
