"""Pose-level noise: the fixed point of fieldcal.trust.pose_noise, including its special case of
one sample per pose (noise from the residuals)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import fieldcal
from fieldcal.trust.pose_noise import estimated_share, solve_pose_variance, with_variances


def _single_shots(seed, n_poses, sigma_a, sigma_m):
    s = fieldcal.simulate("paper", seed=seed, n_poses=n_poses, noise_alpha=(0, 0), samples=(1, 1))
    rng = np.random.default_rng(seed)
    ta, tm = s.truth.predicted_means()
    accel = ta + rng.normal(0, sigma_a, ta.shape)
    mag = tm + rng.normal(0, sigma_m, tm.shape)
    return s, accel, mag


def test_isotropic_noise_is_recovered_per_sensor():
    _, accel, mag = _single_shots(3, 300, 2e-3, 5e-3)
    cal = fieldcal.calibrate(list(accel[:, None]), list(mag[:, None]))
    assert cal.accel.noise_source == cal.mag.noise_source == "residuals"
    sa, sm = np.sqrt(cal.accel.noise_cov[0, 0]), np.sqrt(cal.mag.noise_cov[0, 0])
    assert sa == pytest.approx(2e-3, rel=0.1) and sm == pytest.approx(5e-3, rel=0.1)
    assert np.allclose(cal.accel.noise_cov, sa**2 * np.eye(3))
    # the statistic matches its degrees of freedom at the fixed point
    # J equals its degrees of freedom at the fixed point (which stops within 2 % in q)
    assert cal.diagnostics.statistic == pytest.approx(cal.diagnostics.dof, rel=0.05)
    # χ² standard error of σ²: σ² sqrt(2/ν_s), ν_a + ν_m = 3N − 22
    nu_a = 2 * cal.accel.noise_cov[0, 0] ** 2 / cal.accel.noise_cov_std[0, 0] ** 2
    nu_m = 2 * cal.mag.noise_cov[0, 0] ** 2 / cal.mag.noise_cov_std[0, 0] ** 2
    assert nu_a + nu_m == pytest.approx(3 * 300 - 22, rel=1e-6)
    assert cal.accel.noise_cov_std[0, 1] == 0.0


def test_error_bars_cover_with_residual_noise():
    hits, n = 0, 60
    for seed in range(n):
        s, accel, mag = _single_shots(100 + seed, 24, 3e-3, 3e-3)
        cal = fieldcal.calibrate(list(accel[:, None]), list(mag[:, None]))
        hits += abs(cal.dip_deg - s.truth.dip_deg) <= 1.96 * cal.dip_std_deg
    assert 0.85 <= hits / n <= 1.0


def test_user_noise_replaces_the_estimate_and_one_sensor_alone_works():
    _, accel, mag = _single_shots(5, 30, 2e-3, 2e-3)
    cal = fieldcal.calibrate(list(accel[:, None]), list(mag[:, None]), noise=2e-3)
    assert cal.accel.noise_source == "user" and np.all(cal.accel.noise_cov_std == 0)
    assert cal.options["noise_sources"]["accel"] == "user"
    mixed = fieldcal.calibrate(list(accel[:, None]), list(mag[:, None]), noise={"accel": 2e-3})
    assert mixed.accel.noise_source == "user" and mixed.mag.noise_source == "residuals"
    alone = fieldcal.calibrate(None, list(mag[:, None]))
    assert alone.mag.noise_source == "residuals"
    assert alone.diagnostics.statistic == pytest.approx(30 - 9, rel=0.05)
    assert np.sqrt(alone.mag.noise_cov[0, 0]) == pytest.approx(2e-3, rel=0.4)


def test_fixed_point_is_generic_over_methods():
    """The noise is estimated at the ML point whichever method ran, so it is the same."""
    _, accel, mag = _single_shots(8, 20, 2e-3, 4e-3)
    ml = fieldcal.calibrate(list(accel[:, None]), list(mag[:, None]), robust=False)
    greedy = fieldcal.calibrate(
        list(accel[:, None]), list(mag[:, None]), method="greedy", robust=False
    )
    assert greedy.accel.noise_cov[0, 0] == pytest.approx(ml.accel.noise_cov[0, 0], rel=1e-5)
    assert greedy.mag.noise_cov[0, 0] == pytest.approx(ml.mag.noise_cov[0, 0], rel=1e-5)
    assert greedy.dip_deg == pytest.approx(ml.dip_deg, abs=3 * ml.dip_std_deg)


@pytest.mark.parametrize("seed", range(3))
def test_one_sample_per_pose_variance_is_the_closed_form_newton_reaches(seed):
    """With no within-pose scatter (λ = 0) J(q²) = Σ proj / q²: the root in closed form, the
    number Newton's method converges to when λ is a tiny positive amount."""
    rng = np.random.default_rng(seed)
    proj = rng.chisquare(1, size=(24, 3)) * 1e-6
    target = float(rng.uniform(20, 60))
    closed = solve_pose_variance(proj, np.zeros_like(proj), target)
    assert closed == pytest.approx(proj.sum() / target, rel=1e-15)
    newton = solve_pose_variance(proj, np.full_like(proj, 1e-12 * closed), target)
    assert closed == pytest.approx(newton, rel=1e-9)
    assert solve_pose_variance(np.zeros_like(proj), np.zeros_like(proj), target) == 0.0


def test_the_share_of_the_pose_variance_is_the_mean_of_the_pose_covariances():
    """estimated_share in closed form: q² over the mean of tr(Σ/Δ_i + q² I)/3."""
    s = fieldcal.simulate("paper", seed=2)
    stats = fieldcal.summarize(s.accel, s.mag)
    for name, q2 in (("accel", 3e-6), ("mag", 1e-7)):
        sensor = stats.sensor(name).with_pose_var(q2)
        covs = sensor.mean_covariances()
        per_pose = np.trace(covs, axis1=1, axis2=2).mean() / 3.0
        assert estimated_share(sensor, q2) == pytest.approx(q2 / per_pose, rel=1e-13)
        assert estimated_share(sensor.with_pose_var(0.0), 0.0) == 0.0
    one = dataclasses.replace(stats.sensor("mag"), cov=None).with_pose_var(2e-6)
    assert estimated_share(one, 2e-6) == 1.0  # one sample per pose: q² is all there is


def test_statistics_with_the_variances_they_have_are_the_same_object():
    """What was built from them (the whitened problem) is then reused, not built again."""
    s = fieldcal.simulate("paper", seed=2)
    stats = fieldcal.summarize(s.accel, s.mag)
    assert with_variances(stats, {"accel": 0.0, "mag": 0.0}) is stats
    changed = with_variances(stats, {"accel": 0.0, "mag": 1e-6})
    assert changed is not stats and changed.sensor("accel") is stats.sensor("accel")
    assert changed.sensor("mag").pose_var == 1e-6
