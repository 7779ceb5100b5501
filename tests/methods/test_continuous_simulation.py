"""The hand-waved log simulator (fieldcal.simulation.handwave): its truth explains its readings."""

from __future__ import annotations

import numpy as np

from fieldcal.geometry.frames import GRAVITY
from fieldcal.geometry.rotations import exp_so3
from fieldcal.simulation.handwave import simulate_handwave


def test_readings_follow_the_truth_in_the_gauge():
    log = simulate_handwave(seed=7, seconds=20.0, rests=2)
    truth = log.truth
    R = np.asarray(truth.rotations)
    a = np.column_stack([log.columns["a" + k] for k in "xyz"])
    m = np.column_stack([log.columns["m" + k] for k in "xyz"])
    start, stop = log.rests[0]
    # at rest: accel = K_a R g + b_a + noise; the mean over the rest within 4 standard errors
    pred = (R[start:stop] @ GRAVITY) @ np.asarray(truth.accel.gain).T + truth.accel.bias
    sd = np.sqrt(truth.accel.noise_cov[0, 0] / (stop - start))
    assert np.all(np.abs(np.mean(a[start:stop] - pred, axis=0)) < 4 * sd)
    pred_m = (R @ truth.magnetic) @ np.asarray(truth.mag.gain).T + truth.mag.bias
    resid = m - pred_m
    assert abs(np.std(resid) / np.sqrt(truth.mag.noise_cov[0, 0]) - 1) < 0.05


def test_gyroscope_reads_the_turn_between_samples():
    log = simulate_handwave(seed=7, seconds=10.0)
    R = log.rotations
    dt = 1.0 / log.rate
    # R_{j+1} = Exp(−ω̄ dt) R_j with the mean of the two samples' rates: error far below noise
    step = exp_so3(-0.5 * (log.omega[1:] + log.omega[:-1]) * dt) @ R[:-1]
    err = np.linalg.norm(step - R[1:], axis=(1, 2))
    assert np.max(err) < 0.1 * log.truth.gyro.noise_cov[0, 0] ** 0.5 * dt * 10
    assert not log.rests


def test_a_seed_gives_the_same_log():
    a = simulate_handwave(seed=3, seconds=6.0)
    b = simulate_handwave(seed=3, seconds=6.0)
    assert all(np.array_equal(a.columns[k], b.columns[k]) for k in a.columns)
