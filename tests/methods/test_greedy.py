"""The greedy method of the seed paper (Sec. 4-5): numbers, not shapes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import fieldcal
from fieldcal.geometry.rotations import quaternion_to_matrix
from fieldcal.methods import greedy
from fieldcal.methods.gls import (
    accel_bias_field_design,
    gls,
    mag_bias_field_design,
    symmetric_from_vector,
)
from fieldcal.metrics import reconstruction_error

SEED = 0  # a Table 1 session the greedy method converges on in 90 iterations


@pytest.fixture(scope="module")
def session():
    return fieldcal.simulate("paper", seed=SEED)


@pytest.fixture(scope="module")
def cal(session):
    # the seed paper's model: Eq. 7 noise only, every pose kept
    return fieldcal.calibrate(
        session.accel, session.mag, method="greedy", pose_noise="none", robust=False
    )


def _whitened_lstsq(X, y, cov, counts):
    """Eq. 8 for one linear block, solved by numpy's least squares on whitened rows."""
    L = np.linalg.cholesky(np.linalg.inv(cov))  # Σ⁻¹ = L Lᵀ
    A = np.concatenate([np.sqrt(c) * L.T @ Xi for c, Xi in zip(counts, X, strict=True)])
    b = np.concatenate([np.sqrt(c) * L.T @ yi for c, yi in zip(counts, y, strict=True)])
    return np.linalg.lstsq(A, b, rcond=None)[0]


def _eq8(cal, stats):
    """Eq. 8 written out pose by pose, independently of fieldcal.diagnostics."""
    total = 0.0
    for i in range(stats.n_poses):
        R = cal.rotations[i]
        for sensor, st, field in (
            (cal.accel, stats.accel, cal.gravity),
            (cal.mag, stats.mag, cal.magnetic),
        ):
            r = sensor.gain @ R @ field + sensor.bias - st.means[i]
            total += st.counts[i] * r @ np.linalg.solve(st.cov, r)
    return total


def _random_state(n, rng):
    q = rng.normal(size=(n, 4))
    return dataclasses.replace(
        greedy.initial_state(n),
        accel_gain=np.eye(3) + 0.1 * (lambda A: A + A.T)(rng.normal(size=(3, 3))),
        accel_bias=rng.uniform(-1, 1, 3),
        mag_gain=np.eye(3) + 0.1 * rng.normal(size=(3, 3)),
        mag_bias=rng.uniform(-1, 1, 3),
        h_z=0.7,
        quaternions=q / np.linalg.norm(q, axis=1, keepdims=True),
    )


def test_table1_session_reconstruction_error_below_0_15(session, cal):
    ta, tm = session.truth.predicted_means()
    pa, pm = cal.predicted_means()
    da = reconstruction_error(ta, pa, session.truth.accel.noise_cov, session.counts)
    dm = reconstruction_error(tm, pm, session.truth.mag.noise_cov, session.counts)
    assert da < 0.15 and dm < 0.15
    assert cal.converged and cal.method == "greedy"


def test_result_is_in_fieldcal_gauge(session, cal):
    np.testing.assert_allclose(cal.gravity, [0, 0, -1], atol=1e-12)
    assert abs(np.linalg.norm(cal.magnetic) - 1) < 1e-12 and abs(cal.magnetic[1]) < 1e-12
    np.testing.assert_allclose(cal.accel.gain, cal.accel.gain.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(cal.accel.gain) > 0)
    assert abs(cal.dip_deg - session.truth.dip_deg) < 0.5


def test_reported_cost_is_eq8(session, cal):
    stats = fieldcal.summarize(session.accel, session.mag)
    assert cal.cost == pytest.approx(_eq8(cal, stats), rel=1e-10)
    assert cal.diagnostics.dof == 3 * 15 - 22


def test_pose_order_does_not_matter(session, cal):
    perm = np.random.default_rng(7).permutation(15)
    other = fieldcal.calibrate(
        [session.accel[i] for i in perm],
        [session.mag[i] for i in perm],
        method="greedy",
        pose_noise="none",
        robust=False,
    )
    # Equal to the optimisation's own tolerance (γ = 1e-4 on J): round-off in the pose sums
    # moves the stopping point by ~1e-7, far below the statistical error (~1e-3).
    for a, b in (
        (cal.accel.gain, other.accel.gain),
        (cal.mag.gain, other.mag.gain),
        (cal.accel.bias, other.accel.bias),
        (cal.mag.bias, other.mag.bias),
        (cal.rotations[perm], other.rotations),
    ):
        np.testing.assert_allclose(a, b, atol=1e-5)
    assert abs(cal.dip_deg - other.dip_deg) < 1e-4


def test_bias_field_gls_matches_whitened_lstsq(session):
    stats = fieldcal.summarize(session.accel, session.mag)
    rng = np.random.default_rng(3)
    state = _random_state(15, rng)
    R = state.rotations
    for X, st in (
        (accel_bias_field_design(state.accel_gain, R), stats.accel),
        (mag_bias_field_design(state.mag_gain, R), stats.mag),
    ):
        beta = gls(X, st.means, np.linalg.inv(st.cov), st.counts)
        np.testing.assert_allclose(beta, _whitened_lstsq(X, st.means, st.cov, st.counts), rtol=1e-9)


def test_gain_step_minimises_eq8_over_the_gains(session):
    """Eq. 16, 17 against least squares on a design built from the model itself."""
    stats = fieldcal.summarize(session.accel, session.mag)
    data = greedy.Data.from_stats(stats)
    state = _random_state(15, np.random.default_rng(4))
    new = greedy.gain_step(state, data)
    body_g, body_h = state.rotations @ state.gravity, state.rotations @ state.magnetic
    # Symmetric K_a: the model is linear in its six entries; probe it with unit matrices.
    columns = [body_g @ symmetric_from_vector(np.eye(6)[j]).T for j in range(6)]
    X = np.stack(columns, axis=-1)
    y = stats.accel.means - state.accel_bias
    Ka = symmetric_from_vector(_whitened_lstsq(X, y, stats.accel.cov, stats.accel.counts))
    np.testing.assert_allclose(new.accel_gain, Ka, rtol=1e-9, atol=1e-12)
    X = np.stack([body_h @ np.eye(9)[j].reshape(3, 3).T for j in range(9)], axis=-1)
    y = stats.mag.means - state.mag_bias
    Km = _whitened_lstsq(X, y, stats.mag.cov, stats.mag.counts).reshape(3, 3)
    np.testing.assert_allclose(new.mag_gain, Km, rtol=1e-9, atol=1e-12)
    assert greedy.cost(new, data) < greedy.cost(state, data)


def test_rotation_step_decreases_eq9_to_a_stationary_point(session):
    stats = fieldcal.summarize(session.accel, session.mag)
    data = greedy.Data.from_stats(stats)
    state = _random_state(15, np.random.default_rng(5))
    before = greedy.pose_costs(state, data)
    after_state = greedy.rotation_step(state, data, tol=1e-12, max_iterations=2000)
    after = greedy.pose_costs(after_state, data)
    assert np.all(after <= before) and after.sum() < 0.5 * before.sum()
    # Stationary: no small rotation of any pose lowers Eq. 9 (checked by finite differences).
    q = after_state.quaternions
    for axis in np.eye(3):
        for sign in (1, -1):
            turn = np.concatenate([[np.cos(5e-5)], sign * np.sin(5e-5) * axis])
            w1, v1 = q[:, 0], q[:, 1:]
            w2, v2 = turn[0], turn[1:]
            rotated = np.column_stack(
                [w1 * w2 - v1 @ v2, w1[:, None] * v2 + w2 * v1 + np.cross(v1, v2)]
            )
            assert np.all(
                greedy.pose_costs(after_state, data, rotated) >= after - 1e-6 * (1 + after)
            )


def test_quaternion_gradient_is_analytic_derivative_of_eq9(session):
    stats = fieldcal.summarize(session.accel, session.mag)
    data = greedy.Data.from_stats(stats)
    state = _random_state(15, np.random.default_rng(6))
    frozen = greedy._Frozen.of(state, data)
    J, grad = greedy._quaternion_gradient(state.quaternions, frozen)
    np.testing.assert_allclose(J, greedy.pose_costs(state, data), rtol=1e-12)
    eps, q = 1e-6, state.quaternions
    numeric = np.stack(
        [
            (
                greedy.pose_costs(state, data, q + eps * e)
                - greedy.pose_costs(state, data, q - eps * e)
            )
            / (2 * eps)
            for e in np.eye(4)
        ],
        axis=1,
    )
    np.testing.assert_allclose(grad, numeric, rtol=1e-5, atol=1e-6 * np.abs(grad).max())
    # The rotated vectors agree with the rotation matrices of fieldcal.rotations.
    R = quaternion_to_matrix(q)
    np.testing.assert_allclose(greedy._rotate(q, frozen)[:, 1], R @ state.magnetic, atol=1e-14)


def test_negative_definite_accel_gain_is_flipped_exactly():
    state = _random_state(10, np.random.default_rng(8))
    state = dataclasses.replace(state, accel_gain=-state.accel_gain)  # det < 0: U = −I
    R, Ka, Km, g, h, flipped = greedy.to_fieldcal_gauge(state)
    assert flipped and np.all(np.linalg.eigvalsh(Ka) > 0)
    pa, pm = state.predicted_means()
    np.testing.assert_allclose((R @ g) @ Ka.T + state.accel_bias, pa, atol=1e-12)
    np.testing.assert_allclose((R @ h) @ Km.T + state.mag_bias, pm, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)


def test_noise_free_session_recovers_the_means():
    session = fieldcal.simulate("paper", seed=SEED, noise_alpha=(0, 0))
    cal = fieldcal.calibrate(session.accel, session.mag, method="greedy", noise=1e-3)
    ta, tm = session.truth.predicted_means()
    pa, pm = cal.predicted_means()
    # What greedy really reaches with γ = 1e-4 on J in units of (1e-3)²: ~4e-7 here.
    assert np.abs(pa - ta).max() < 2e-6 and np.abs(pm - tm).max() < 2e-6
    assert cal.accel.noise_source == "user"


def test_iteration_cap_warns_and_reports_not_converged(session):
    with pytest.warns(UserWarning, match="max_iterations"):
        cal = fieldcal.calibrate(session.accel, session.mag, method="greedy", max_iterations=3)
    assert not cal.converged and cal.iterations == 3


def test_a_slow_descent_stops_at_the_time_limit():
    """Seed 1 of Table 1 descends for minutes (h_z moves slowly; the γ rule is far): the time
    limit stops it, says so, and the verdict reports it. Scaled by 1e-30 (the fuzz case) the
    data reach the method at the same digits (a power of two), so the same limit applies."""
    session = fieldcal.simulate("paper", seed=1)
    tiny = 1e-30
    with pytest.warns(UserWarning, match="time limit of 0.2 s"):
        cal = fieldcal.calibrate(
            [a * tiny for a in session.accel],
            [m * tiny for m in session.mag],
            method="greedy",
            max_seconds=0.2,
            robust=False,
        )
    assert not cal.converged and cal.message.startswith("time limit reached")
    assert cal.iterations < greedy.run_greedy.__defaults__[1]  # stopped well before the cap
    assert "not_converged" in {r.code for r in cal.verdict.reasons}
    assert cal.options["max_seconds"] == 0.2
    with pytest.raises(ValueError, match="max_seconds must be a positive number"):
        fieldcal.calibrate(session.accel, session.mag, method="greedy", max_seconds=0)


def test_gamma_history_gives_every_larger_gamma():
    """One small-γ run with a callback stops, for a larger γ, exactly where that run stops."""
    session = fieldcal.simulate("paper", seed=3)
    stats = fieldcal.summarize(session.accel, session.mag)
    history = []
    greedy.run_greedy(stats, 1e-6, 2000, callback=lambda k, J, s, t: history.append(J))
    direct = greedy.run_greedy(stats, 1e-1, 2000)
    costs = np.array(history)
    k = int(np.flatnonzero(costs[:-1] - costs[1:] <= 1e-1)[0]) + 1
    assert direct.iterations == k and direct.costs[-1] == costs[k]


def test_bad_input_raises(session):
    with pytest.raises(ValueError, match="at least 8"):
        fieldcal.calibrate(session.accel[:7], session.mag[:7], method="greedy")
    with pytest.raises(ValueError, match="method='mle'"):
        fieldcal.calibrate(session.accel, None, method="greedy")
    with pytest.raises(ValueError, match="unknown option"):
        fieldcal.calibrate(session.accel, session.mag, method="greedy", step=1.0)
    # One sample per pose and no noise given: the method itself refuses (fieldcal.calibrate
    # wraps it in the pose-noise fixed point of fieldcal.trust instead).
    one_shot = fieldcal.summarize([a[:1] for a in session.accel], [m[:1] for m in session.mag])
    with pytest.raises(ValueError, match="scatter"):
        greedy.fit(one_shot)


def test_the_same_poses_give_the_same_file():
    """Nothing run-dependent (wall time) goes into a result: the same poses give the same JSON
    document but for its ``created`` stamp (``fieldcal batch`` relies on it)."""
    session = fieldcal.simulate("paper", seed=8)
    docs = [
        fieldcal.calibrate(session.accel, session.mag, method="greedy").to_dict() for _ in range(2)
    ]
    for doc in docs:
        doc.pop("created")
    assert docs[0] == docs[1]
