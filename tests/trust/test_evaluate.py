"""Eq. 8's model evaluated at a calibration (fieldcal.trust.evaluate): zero residuals at the
truth's own pose means, a known shift of one pose mean read back as its residual and its
whitened cost ``dᵀ (Σ/Δ)⁻¹ d``, and the expected share of J summing to the degrees of freedom."""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.stats.pose_stats import stats_from_means, summarize
from fieldcal.trust.evaluate import evaluate

N = 12


def _session():
    return fieldcal.simulate("paper", seed=1, n_poses=N)


def _exact_stats(s, accel_shift=None, pose=0):
    """Pose means exactly the truth's prediction (one optionally shifted), with the true
    per-sample covariances and counts."""
    a, m = s.truth.predicted_means()
    if accel_shift is not None:
        a = a.copy()
        a[pose] += accel_shift
    t = s.truth
    return stats_from_means(
        a, m, counts=s.counts, accel_cov=t.accel.noise_cov, mag_cov=t.mag.noise_cov
    )


def test_the_truths_own_means_leave_no_residual():
    s = _session()
    ev = evaluate(s.truth, _exact_stats(s), "accel")
    assert ev.whitened.shape == (N, 6)
    assert np.abs(ev.whitened).max() < 1e-10
    assert ev.sensor_cost("accel") < 1e-20 and ev.sensor_cost("mag") < 1e-20


def test_a_shifted_pose_mean_is_its_residual_and_whitened_cost():
    s = _session()
    d = np.array([0.01, -0.02, 0.005])
    ev = evaluate(s.truth, _exact_stats(s, d, pose=3), "accel")
    np.testing.assert_allclose(ev.raw["accel"][3], -d, atol=1e-12)  # model − mean
    assert np.abs(np.delete(ev.raw["accel"], 3, axis=0)).max() < 1e-12
    expected = d @ np.linalg.solve(s.truth.accel.noise_cov / s.counts[3], d)
    assert ev.pose_cost[3] == pytest.approx(expected, rel=1e-9)
    assert ev.sensor_cost("accel") == pytest.approx(expected, rel=1e-9)
    assert ev.sensor_cost("mag") < 1e-20
    with pytest.raises(ValueError):
        ev.pose_cost[0] = 1.0  # read-only: computed once, shared


def test_directions_are_the_unit_readings_and_the_dof_shares_add_up():
    s = _session()
    stats = summarize(s.accel, s.mag)
    ev = evaluate(s.truth, stats, "accel")
    for sensor in ("accel", "mag"):
        sc = s.truth.sensor(sensor)
        fields = s.truth.rotations @ s.truth.reference(sensor)
        readings = fields @ np.asarray(sc.gain).T
        expected = readings / np.linalg.norm(readings, axis=1, keepdims=True)
        np.testing.assert_allclose(ev.directions[sensor], expected, atol=1e-12)
    # 3N − tr(H_ss) per sensor: together the degrees of freedom of Eq. 8
    assert sum(ev.dof_share().values()) == pytest.approx(ev.dof, rel=1e-9)
