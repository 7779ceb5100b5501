"""The fused normal equations and Schur step of :mod:`fieldcal.likelihood.levenberg` (issue 24,
item 3) against the dense algebra they stand for, and the batched exp map against SciPy.

The fused forms (``[U | W | gp] = Jpᵀ [Jp | Jg | e]``, ``[Y | z] = U⁻¹ [W | gp]``, the
predicted decrease ``δᵀ(Λδ − g)``) reorder sums of a few dozen products, so they agree with
the dense ones to a small multiple of double rounding times the system's condition: 1e-9
relative (the issue's "same result") is ~10⁶ above that and far below any real change.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fieldcal.geometry.rotations import random_rotations
from fieldcal.likelihood.levenberg import damped_inverse, normal_equations, solve_step
from fieldcal.likelihood.pose_model import (
    Problem,
    State,
    build_problem,
    exp_map,
    field,
    jacobians,
    model_readings,
    raw_residuals,
    residuals,
    rotation_basis,
    whiten,
)
from fieldcal.simulation.warmup import simulate_warmup
from fieldcal.stats.pose_stats import summarize
from fieldcal.stats.pose_temperature import PoseTemperature, pose_temperatures

RTOL = 1e-9

KINDS = [
    (("accel", "mag"), None),
    (("accel", "mag"), {"accel": 2, "mag": 1}),
    (("accel",), None),
    (("mag",), {"mag": 1}),
]


def _problem_and_state(kind: int, seed: int) -> tuple[Problem, State]:
    sensors, orders = KINDS[kind]
    n = 12
    w = simulate_warmup(seed=seed, n_poses=n)
    stats = summarize(w.accel if "accel" in sensors else None, w.mag if "mag" in sensors else None)
    if orders is not None:
        stats = stats.with_temperature(PoseTemperature(pose_temperatures(w.temperature, n), orders))
    problem = build_problem(stats, sensors[0])
    rng = np.random.default_rng(seed)
    gains = {s: np.eye(3) + 0.1 * rng.standard_normal((3, 3)) for s in problem.sensors}
    gains[problem.frame] = 0.5 * (gains[problem.frame] + gains[problem.frame].T)
    biases = {s: 0.1 * rng.standard_normal(3) for s in problem.sensors}
    temps = {s: 1e-3 * rng.standard_normal((problem.temp_order(s), 3)) for s in problem.temp_slice}
    state = State(gains, biases, 0.9, random_rotations(n, rng), temps)
    return problem, state


def _close(a: object, b: object) -> None:
    b = np.asarray(b)
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * float(np.abs(b).max()))  # type: ignore[arg-type]


@pytest.mark.parametrize("kind", range(len(KINDS)))
def test_the_normal_blocks_are_the_dense_products(kind: int) -> None:
    problem, state = _problem_and_state(kind, 3 + kind)
    e = residuals(problem, state)
    ne = normal_equations(problem, state, e)
    Jp, Jg = jacobians(problem, state, rotation_basis(problem, state))
    _close(ne.Jp, Jp)
    _close(ne.Jg, Jg)
    flat = Jg.reshape(-1, problem.n_global)
    _close(ne.U, np.einsum("nmi,nmj->nij", Jp, Jp))
    _close(ne.W, np.einsum("nmi,nmj->nij", Jp, Jg))
    _close(ne.V, np.einsum("ri,rj->ij", flat, flat))
    _close(ne.gp, np.einsum("nmi,nm->ni", Jp, e))
    _close(ne.gg, np.einsum("ri,r->i", flat, e.ravel()))


@pytest.mark.parametrize("kind", range(len(KINDS)))
@pytest.mark.parametrize("lam", [0.0, 1e-4, 10.0])
def test_the_schur_step_solves_the_damped_system(kind: int, lam: float) -> None:
    """The step solves ``(H + Λ)δ = −g`` with the whole (pN + G) matrix, and the predicted
    decrease is ``J(0) − J_lin(δ) = −2δᵀg − δᵀHδ`` (``J_lin(δ) = ‖e + Jδ‖²``)."""
    problem, state = _problem_and_state(kind, 7 + kind)
    e = residuals(problem, state)
    ne = normal_equations(problem, state, e)
    dg, dp, pred = solve_step(ne, lam)
    n, p, G = problem.n, ne.U.shape[-1], problem.n_global
    J = np.zeros((e.size, n * p + G))
    m = e.shape[1]
    for i in range(n):
        J[i * m : (i + 1) * m, i * p : (i + 1) * p] = ne.Jp[i]
    J[:, n * p :] = np.asarray(ne.Jg).reshape(-1, G)
    H = J.T @ J
    g = J.T @ e.ravel()
    d = np.diag(H)
    A = H + np.diag(lam * d + 1e-12 * (1.0 + d))
    delta = np.linalg.solve(A, -g)
    _close(dp.ravel(), delta[: n * p])
    _close(dg, delta[n * p :])
    # the linear model's decrease, computed from the dense matrices (not the solver's formula)
    _close(pred, -2.0 * delta @ g - delta @ H @ delta)


def test_exp_map_is_rodrigues_on_both_sides_of_the_series_switch() -> None:
    rng = np.random.default_rng(5)
    directions = rng.standard_normal((40, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    angles = np.concatenate([np.geomspace(1e-9, 3.0, 20), np.geomspace(1e-6, 1e-3, 20)])
    omega = directions * angles[:, None]
    for batch in (omega, omega[angles > 1e-3]):  # mixed (series used) and all large
        R = exp_map(batch)
        expected = Rotation.from_rotvec(batch).as_matrix()
        # entries are O(1): a few roundings of the trigonometric terms
        assert np.abs(R - expected).max() <= 1e-14
        assert np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max() <= 1e-14


@pytest.mark.parametrize("p", [3, 2])
def test_the_closed_form_damped_inverse_is_the_inverse_and_flags_singular_blocks(p: int) -> None:
    """The adjugate inverses of the damped pose blocks equal LAPACK's (np.linalg.inv) for two
    problems stacked with their own λ; a block with a zero determinant marks its problem
    singular (np.linalg.inv raises on it) and leaves the other problem alone."""
    rng = np.random.default_rng(11 + p)
    A = rng.standard_normal((2, 4, 5, p))
    U = A.transpose(0, 1, 3, 2) @ A  # Jpᵀ Jp: symmetric positive definite, condition ~ 10
    # diagonal −1 is unchanged by damping at λ = 0 (−1e-12 + 1e-12 = 0 exactly), so this block
    # stays singular: [[-1, 1], [1, -1]] (with −1 below it for p = 3)
    U[1, 2] = np.diag(np.full(p, -1.0))
    U[1, 2, 0, 1] = U[1, 2, 1, 0] = 1.0
    lam = np.array([1e-3, 0.0])[:, None, None]
    inverse, damp_p, singular = damped_inverse(U, lam)
    assert singular.tolist() == [False, True]
    damped = U.copy()
    idx = np.arange(p)
    damped[..., idx, idx] += damp_p
    _close(damp_p, (lam + 1e-12) * U[..., idx, idx] + 1e-12)
    _close(inverse[0], np.linalg.inv(damped[0]))
    _close(inverse[1, [0, 1, 3]], np.linalg.inv(damped[1, [0, 1, 3]]))
    assert np.isnan(inverse[1, 2]).all()
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.inv(damped[1, 2])
    # one problem alone: a scalar λ, no problem axis
    alone, _, flag = damped_inverse(U[0], 1e-3)
    _close(alone, inverse[0])
    assert not flag


@pytest.mark.parametrize("kind", range(len(KINDS)))
def test_the_raw_residuals_whitened_are_the_residuals(kind: int) -> None:
    """``e = L⁻¹ r``: the raw residuals (from the model's readings ``K R f``) whiten to the
    residuals, and ``L e`` with the Cholesky factor of each pose mean's covariance gives them
    back (what the pose table reports in raw units)."""
    problem, state = _problem_and_state(kind, 13 + kind)
    readings = model_readings(problem, state)
    raw = raw_residuals(problem, state, readings.copy())  # it turns readings into residuals
    e = residuals(problem, state)
    _close(whiten(problem, raw), e)
    for k, s in enumerate(problem.sensors):
        chol = np.linalg.inv(problem.linv[s])
        _close(raw[k], (chol @ e[:, 3 * k : 3 * k + 3, None])[..., 0])
        _close(readings[k], state.rotations @ field(problem, s, state.dip) @ state.gains[s].T)
