"""A synthetic hand-waved log (fieldcal.simulation.handwave): without noise or shake, the truth's
own corrections give the fields turned by the truth's trajectory exactly, its gyroscope's rates
turn one sample's rotation into the next, and rests are still."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.geometry.rotations import exp_so3, log_so3
from fieldcal.simulation.handwave import simulate_handwave


@pytest.fixture(scope="module")
def log():
    return simulate_handwave(
        seed=3, seconds=8.0, noise_scale=0.0, shake=0.0, rests=1, gyro_noise=0.0
    )


def _raw(log, prefix):
    return np.column_stack([log.columns[prefix + a] for a in "xyz"])


def test_corrected_fields_are_the_trajectory_turning_the_reference_fields(log):
    truth = log.truth
    R = truth.rotations
    assert R.shape == (log.n, 3, 3)
    np.testing.assert_allclose(truth.correct_accel(_raw(log, "a")), R @ truth.gravity, atol=1e-9)
    np.testing.assert_allclose(truth.correct_mag(_raw(log, "m")), R @ truth.magnetic, atol=1e-9)
    assert np.linalg.norm(truth.gravity) == pytest.approx(1.0)
    assert np.linalg.norm(truth.magnetic) == pytest.approx(1.0)


def test_the_gyroscope_turns_each_rotation_into_the_next(log):
    truth = log.truth
    omega = truth.correct_gyro(_raw(log, "g"))  # rad/s in the gauge's body frame
    R = truth.rotations
    dt = 1.0 / log.rate
    worst = 0.0
    for k in range(0, log.n - 1, 37):
        # dR/dt = −[ω]× R, the rate held at the mean of the step's two ends
        step = exp_so3(-0.5 * (omega[k] + omega[k + 1]) * dt) @ R[k]
        worst = max(worst, float(np.linalg.norm(log_so3(step @ R[k + 1].T))))
    turned = np.median(np.linalg.norm(omega, axis=1)) * dt
    # the rate at the middle of each step (holding either end instead misses by ~10 %)
    assert worst < 0.01 * turned


def test_rests_are_still(log):
    ((start, stop),) = log.rests
    assert stop - start >= 2 * log.rate  # 3 s asked, faded at the ends
    middle = slice(start + (stop - start) // 3, stop - (stop - start) // 3)
    assert np.abs(log.omega[middle]).max() < 1e-9
    still = _raw(log, "a")[middle]
    assert np.ptp(still, axis=0).max() < 1e-9  # no noise, no motion: one reading
