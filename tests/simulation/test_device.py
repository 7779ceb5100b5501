"""The simulated board (fieldcal.simulation.device): still samples average to the model's
reading within their noise, the turn's gyroscope rates integrate to the turn, a seed gives the
same rows, and the gyroscope's truth moves into fieldcal's gauge."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import fieldcal
from fieldcal.geometry.rotations import exp_so3, log_so3
from fieldcal.simulation.device import Device, geodesic


def _rotation(seed: int) -> np.ndarray:
    return Rotation.random(random_state=seed).as_matrix()


def test_still_samples_average_to_the_model_reading():
    device = Device(seed=3, rate=200.0)
    R = _rotation(1)
    rows = device.still(R, 20.0)
    assert rows.n == 4000 and np.allclose(rows.t[:2], [0.0, 0.005])
    d = device.drawn
    for data, gain, bias, field, cov in (
        (rows.accel, d["accel_gain"], d["accel_bias"], d["gravity"], d["accel_cov"]),
        (rows.mag, d["mag_gain"], d["mag_bias"], d["magnetic"], d["mag_cov"]),
    ):
        expected = np.asarray(gain) @ R @ np.asarray(field) + np.asarray(bias)
        tolerance = 5 * np.sqrt(np.diag(np.asarray(cov)) / rows.n)
        assert np.all(np.abs(data.mean(axis=0) - expected) < tolerance)
    g = device.gyro_drawn
    assert np.all(np.abs(rows.gyro.mean(axis=0) - g.bias) < 5 * g.noise_std / np.sqrt(rows.n))
    assert device.time == pytest.approx(20.0)


def test_the_turns_rates_integrate_to_the_turn():
    start, stop = _rotation(2), _rotation(3)
    m, rate = 400, 100.0
    rotations, omega = geodesic(start, stop, m, rate)
    # dR/dt = −[ω]× R about a fixed axis: the rates sum to the turn (midpoint rule)
    phi = log_so3(stop @ start.T)
    np.testing.assert_allclose(-omega.sum(axis=0) / rate, phi, atol=1e-4)
    # and neighbouring rotations differ by the mean rate over one step
    for k in (0, m // 2, m - 2):
        step = -0.5 * (omega[k] + omega[k + 1]) / rate
        np.testing.assert_allclose(rotations[k + 1], exp_so3(step) @ rotations[k], atol=1e-6)
    assert np.linalg.norm(omega[0]) < 0.01 * np.linalg.norm(omega[m // 2])  # at rest at the ends


def test_a_seed_gives_the_same_rows_and_the_sessions_truth():
    a, b = Device(seed=5), Device(seed=5)
    R0, R1 = _rotation(4), _rotation(5)
    for x, y in ((a.still(R0, 1.0), b.still(R0, 1.0)), (a.move(R0, R1, 2.0), b.move(R0, R1, 2.0))):
        np.testing.assert_array_equal(x.accel, y.accel)
        np.testing.assert_array_equal(x.gyro, y.gyro)
    assert a.truth == fieldcal.simulate("paper", seed=5).truth
    assert set(a.still(R0, 0.1).columns()) == {
        "t",
        "ax",
        "ay",
        "az",
        "gx",
        "gy",
        "gz",
        "mx",
        "my",
        "mz",
    }


def test_ideal_gyroscope_and_the_gauge():
    device = Device(seed=6, ideal_gyro=True, gyro_noise=0.0)
    g = device.gyro_drawn
    np.testing.assert_array_equal(g.gain, np.eye(3))
    np.testing.assert_array_equal(g.bias, np.zeros(3))
    omega = np.array([[0.1, -0.2, 0.3]])
    assert np.array_equal(g.read([0.0], omega, np.zeros((1, 3))), omega)
    # in the gauge the same rate is read: ω_gauge = U ω_drawn, gain_gauge = gain Uᵀ
    gauge = device.gyro_truth
    U = gauge.gain.T  # ideal: gain_gauge = Uᵀ
    np.testing.assert_allclose(U @ U.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(gauge.read([0.0], omega @ U.T, np.zeros((1, 3))), omega, atol=1e-15)
    assert gauge.in_gauge(device.drawn) is gauge


def test_bad_rotations_and_rates_are_refused():
    device = Device(seed=7)
    with pytest.raises(ValueError, match="3x3 orthogonal"):
        device.still(np.ones((3, 3)), 1.0)
    with pytest.raises(ValueError, match="determinant \\+1"):
        device.still(np.diag([1.0, 1.0, -1.0]), 1.0)
    with pytest.raises(ValueError, match="rate must be positive"):
        Device(seed=7, rate=0.0)
