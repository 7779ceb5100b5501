"""Eq. 8's static-pose model (fieldcal.likelihood.pose_model): the analytic Jacobian against
central differences of the residuals through the model's own step, for the joint and the
one-sensor problems; residuals zero at exact means; Rodrigues' formula against scipy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import fieldcal
from fieldcal.likelihood import pose_model as pm
from fieldcal.stats.pose_stats import stats_from_means, summarize


def _problem(sensors: str, seed: int = 2):
    s = fieldcal.simulate("paper", seed=seed, n_poses=9)
    stats = summarize(s.accel, s.mag if sensors == "joint" else None)
    problem = pm.build_problem(stats, "accel")
    state = pm.state_from_calibration(problem, s.truth)
    # a state off the truth (globals moved), so every term of the Jacobian is exercised
    rng = np.random.default_rng(seed)
    P = 3 if problem.joint else 2
    basis = pm.rotation_basis(problem, state)
    moved = 0.01 * rng.normal(size=problem.n_global)
    state = pm.apply_step(problem, state, moved, np.zeros((problem.n, P)), basis)
    return problem, state


@pytest.mark.parametrize("sensors", ["joint", "accel"])
def test_the_jacobian_is_the_residuals_derivative(sensors):
    problem, state = _problem(sensors)
    basis = pm.rotation_basis(problem, state)
    rot, glob = pm.jacobians(problem, state, basis)
    P = rot.shape[-1]
    assert P == (3 if sensors == "joint" else 2) and glob.shape[-1] == problem.n_global
    h = 1e-6
    for g in range(problem.n_global):
        dg = np.zeros(problem.n_global)
        dg[g] = h
        zero = np.zeros((problem.n, P))
        up = pm.residuals(problem, pm.apply_step(problem, state, dg, zero, basis))
        down = pm.residuals(problem, pm.apply_step(problem, state, -dg, zero, basis))
        np.testing.assert_allclose(glob[..., g], (up - down) / (2 * h), rtol=1e-5, atol=1e-5)
    for j in range(P):  # every pose's rotation at once: each pose's rows depend on its own
        dp = np.zeros((problem.n, P))
        dp[:, j] = h
        zero = np.zeros(problem.n_global)
        up = pm.residuals(problem, pm.apply_step(problem, state, zero, dp, basis))
        down = pm.residuals(problem, pm.apply_step(problem, state, zero, -dp, basis))
        np.testing.assert_allclose(rot[..., j], (up - down) / (2 * h), rtol=1e-5, atol=1e-5)


def test_exact_means_leave_zero_residuals_and_the_dof_is_counted():
    s = fieldcal.simulate("paper", seed=4, n_poses=9)
    a, m = s.truth.predicted_means()
    t = s.truth
    stats = stats_from_means(
        a, m, counts=s.counts, accel_cov=t.accel.noise_cov, mag_cov=t.mag.noise_cov
    )
    problem = pm.build_problem(stats, "accel")
    e = pm.residuals(problem, pm.state_from_calibration(problem, t))
    assert np.abs(e).max() < 1e-10
    assert problem.dof == 3 * 9 - 22 and problem.joint
    costs = pm.sensor_costs(problem, e)
    assert set(costs) == {"accel", "mag"} and max(costs.values()) < 1e-20


def test_rodrigues_against_scipy_at_small_and_large_angles():
    rng = np.random.default_rng(5)
    omega = np.vstack([rng.normal(size=(20, 3)), 1e-6 * rng.normal(size=(5, 3)), np.zeros((1, 3))])
    np.testing.assert_allclose(
        pm.exp_map(omega), Rotation.from_rotvec(omega).as_matrix(), atol=1e-14
    )
