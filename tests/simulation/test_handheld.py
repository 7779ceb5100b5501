"""The hand-held test bed's physics, checked by computations of its own: finite differences of
the trajectory it returns reproduce the specific force and the rate it reads, rests read the
static model, and a turn about the sensor's own origin feels no lever arm."""

import numpy as np
import pytest

from fieldcal.geometry.frames import GRAVITY
from fieldcal.geometry.rotations import log_so3
from fieldcal.simulation.handheld import simulate_handheld


def _relative_turns(R: np.ndarray) -> np.ndarray:
    """Rotation vectors ``φ_k`` with ``R_{k+1} = Exp(−φ_k) R_k`` (the turn between samples)."""
    return -log_so3(R[1:] @ np.transpose(R[:-1], (0, 2, 1)))


def test_finite_differences_of_the_trajectory_give_the_specific_force():
    """The sensor at ``p + Rᵀ r`` (world), differentiated twice numerically, minus gravity,
    rotated into the body: the specific force the accelerometer was given, lever arm and all."""
    rate = 2000.0
    log = simulate_handheld(
        3,
        seconds=4.0,
        rate=rate,
        internal_rate=rate,
        max_rate=20.0,
        lever_arm=0.15,
        translation_rms=1.0,
    )
    R, r = log.rotations, log.lever_arm
    sensor = log.position + np.einsum("nji,j->ni", R, r)
    h = 1.0 / rate
    accel_world = (sensor[2:] - 2 * sensor[1:-1] + sensor[:-2]) / h**2
    expected = np.einsum("nij,nj->ni", R[1:-1], accel_world + GRAVITY * log.gravity)
    got = log.specific_force[1:-1]
    lever = np.linalg.norm(np.cross(log.omega, np.cross(log.omega, r)), axis=1)
    assert lever.max() > 20.0  # the test means something: the centripetal term is large
    # central differences err by h²/12 of the fourth derivative: (20 rad/s)⁴·0.15 m·h²/12 ≈ 5e-4
    assert np.max(np.linalg.norm(got - expected, axis=1)) < 0.01


def test_the_trajectory_is_the_integral_of_the_rate():
    """Each sample-to-sample turn equals the rate at the interval's middle times Δt to second
    order, and a finer integration grid gives the same trajectory (the Magnus step converged)."""
    coarse = simulate_handheld(5, seconds=6.0, rate=200.0, max_rate=15.0)
    fine = simulate_handheld(5, seconds=6.0, rate=200.0, max_rate=15.0, internal_rate=8000.0)
    drift = log_so3(fine.rotations @ np.transpose(coarse.rotations, (0, 2, 1)))
    assert np.max(np.linalg.norm(drift, axis=1)) < 1e-7
    dt = 1.0 / 200.0
    phi = _relative_turns(coarse.rotations)
    mid = 0.5 * (coarse.omega[1:] + coarse.omega[:-1])  # error O(dt² ω̈), ~1e-4 rad/s here
    assert np.max(np.linalg.norm(phi / dt - mid, axis=1)) < 0.02
    assert np.max(np.linalg.norm(coarse.omega, axis=1)) > 14.0


def test_interval_mean_sampling_reads_the_turn_that_follows_the_sample():
    rate = 100.0
    log = simulate_handheld(7, seconds=10.0, rate=rate, max_rate=10.0, gyro_sampling="mean")
    phi = _relative_turns(log.rotations)
    # the turn over [t_k, t_k+1) is ∫ω dt up to the coning term ~ dt² |ω||ω̇| / 12
    coning = (
        (1 / rate) ** 2
        * np.linalg.norm(log.omega[:-1], axis=1)
        * np.linalg.norm(log.omega_dot[:-1], axis=1)
    )
    err = np.linalg.norm(phi * rate - log.omega_read[:-1], axis=1)
    assert np.all(err < 0.05 * rate * coning + 1e-3)
    instant = simulate_handheld(7, seconds=10.0, rate=rate, max_rate=10.0)
    assert np.allclose(instant.omega_read, instant.omega)
    assert np.median(np.linalg.norm(instant.omega_read - log.omega_read, axis=1)) > 0.05


def test_at_rest_the_readings_are_the_static_model():
    log = simulate_handheld(11, seconds=30.0, rests=3, max_rate=8.0, translation_rms=0.8)
    assert len(log.rests) == 3
    a = np.column_stack([log.columns[k] for k in ("ax", "ay", "az")])
    g = np.column_stack([log.columns[k] for k in ("gx", "gy", "gz")])
    for start, stop in log.rests:
        R = log.rotations[start]
        assert np.allclose(log.rotations[start:stop], R, atol=1e-12)
        assert np.allclose(log.position[start:stop], log.position[start], atol=1e-12)
        n = stop - start
        sa = np.sqrt(log.truth.accel.noise_cov[0, 0])
        expected = log.accel_gain @ R @ (GRAVITY * log.gravity) + log.accel_bias
        assert np.all(np.abs(a[start:stop].mean(axis=0) - expected) < 5 * sa / np.sqrt(n))
        sg = np.sqrt(log.truth.gyro.noise_cov[0, 0])
        assert np.all(np.abs(g[start:stop].mean(axis=0) - log.gyro_bias) < 5 * sg / np.sqrt(n))


def test_a_turn_about_the_sensors_own_origin_feels_only_gravity():
    log = simulate_handheld(
        13, seconds=5.0, lever_arm=np.zeros(3), translation_rms=0.0, max_rate=20.0
    )
    assert np.allclose(log.acceleration, 0.0) and np.allclose(log.position, log.position[0])
    assert np.allclose(np.linalg.norm(log.specific_force, axis=1), log.gravity, rtol=1e-12)
    up = np.einsum("nij,j->ni", log.rotations, GRAVITY * log.gravity)
    assert np.allclose(log.specific_force, up, atol=1e-9)
    # the same motion with an arm differs by exactly the two lever-arm terms
    arm = np.array([0.0, 0.1, 0.0])
    moved = simulate_handheld(13, seconds=5.0, lever_arm=arm, translation_rms=0.0, max_rate=20.0)
    extra = np.cross(moved.omega_dot, arm) + np.cross(moved.omega, np.cross(moved.omega, arm))
    assert np.allclose(moved.specific_force - up, extra, atol=1e-9)


def test_the_motion_has_the_requested_size():
    for seed, (rms, reach) in enumerate([(0.3, 1.0), (1.0, 1.0), (1.0, 0.05)]):
        log = simulate_handheld(
            seed,
            seconds=60.0,
            translation_rms=rms,
            max_excursion=reach,
            max_rate=20.0,
            lever_arm=(0.03, 0.15),
        )
        got_rms = float(np.sqrt(np.mean(np.sum(log.acceleration**2, axis=1))))
        centre_dist = np.linalg.norm(log.position - log.position.mean(axis=0), axis=1)
        assert centre_dist.max() < 2 * reach
        if reach >= 1.0:
            assert abs(got_rms - rms) < 0.05 * rms  # sampled at 100 Hz instead of 1 kHz
        else:
            assert got_rms < rms  # shrunk to stay within reach
        assert 19.0 < np.max(np.linalg.norm(log.omega, axis=1)) <= 20.0 + 1e-9
        assert 0.03 <= np.linalg.norm(log.lever_arm) <= 0.15


def test_the_truth_in_fieldcals_gauge_predicts_the_readings():
    log = simulate_handheld(17, seconds=20.0, lever_arm=np.zeros(3), translation_rms=0.0)
    t = log.truth
    a = np.column_stack([log.columns[k] for k in ("ax", "ay", "az")])
    m = np.column_stack([log.columns[k] for k in ("mx", "my", "mz")])
    pred_a = np.einsum("ij,njk,k->ni", t.accel.gain, t.rotations, t.gravity) + t.accel.bias
    pred_m = np.einsum("ij,njk,k->ni", t.mag.gain, t.rotations, t.magnetic) + t.mag.bias
    za = (a - pred_a) / np.sqrt(t.accel.noise_cov[0, 0])
    zm = (m - pred_m) / np.sqrt(t.mag.noise_cov[0, 0])
    assert 0.9 < za.std() < 1.1 and 0.9 < zm.std() < 1.1
    assert (
        abs(np.degrees(np.arcsin(t.magnetic[2] / np.linalg.norm(t.magnetic))) - log.dip_deg) < 1e-9
    )
    # one body rotation U takes the drawn frame to the gauge's (the world is already in its
    # gauge: g down, h north-down): K_gauge U = K_drawn for both the accelerometer and gyroscope
    U = t.rotations @ np.transpose(log.rotations, (0, 2, 1))
    assert np.allclose(U, U[0], atol=1e-9) and np.allclose(U[0] @ U[0].T, np.eye(3), atol=1e-9)
    assert np.allclose(t.gyro.gain @ U[0], log.gyro_gain, atol=1e-9)
    assert np.allclose(t.accel.gain @ U[0] / log.gravity, log.accel_gain, atol=1e-9)
    assert np.allclose(U[0] @ log.lever_arm, log.lever_arm_gauge)


def test_seeded_and_refuses_bad_arguments():
    a, b = simulate_handheld(21, seconds=2.0), simulate_handheld(21, seconds=2.0)
    assert all(np.array_equal(a.columns[k], b.columns[k]) for k in a.columns)
    assert not np.array_equal(a.columns["ax"], simulate_handheld(22, seconds=2.0).columns["ax"])
    assert "temp" in simulate_handheld(1, seconds=2.0, temperature=(20.0, 35.0)).columns
    with pytest.raises(ValueError, match="gyro_sampling"):
        simulate_handheld(1, seconds=1.0, gyro_sampling="middle")
    with pytest.raises(ValueError, match="positive"):
        simulate_handheld(1, seconds=0.0)
