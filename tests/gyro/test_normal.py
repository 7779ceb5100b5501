"""The gyroscope's structured linear algebra (linear in the number of poses) against the dense
computation it replaces: the segments' covariance, the normal equations, the damped step, the
gain's information and the covariance; the blocked quaternion scan; the progress count."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import fieldcal
from fieldcal.gyro import fit_gyro
from fieldcal.gyro.banded import Arrow
from fieldcal.gyro.data import build_segments, check_rows, pose_statistics
from fieldcal.gyro.integrate import cumulative_quaternions, quaternion_multiply
from fieldcal.gyro.model import SegmentModel
from fieldcal.gyro.noise import PoseErrors, SegmentNoise
from fieldcal.gyro.normal import NormalSystem
from fieldcal.likelihood.cramer_rao import pose_rotation_covariance, pose_rotation_factors
from fieldcal.simulation.continuous import simulate_continuous

RTOL = 1e-9


@pytest.fixture(scope="module")
def small():
    sim = simulate_continuous("paper", seed=2, n_poses=8)
    c = sim.columns
    t, g = c["t"], np.column_stack([c["gx"], c["gy"], c["gz"]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = fieldcal.calibrate(sim.session.accel, sim.session.mag)
    assert not cal.rejected
    return sim, t, g, cal


def _close(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert np.max(np.abs(a - b)) <= RTOL * np.max(np.abs(b)), np.max(np.abs(a - b))


def test_factored_pose_covariance_is_the_dense_one(small):
    _, _, _, cal = small
    _close(pose_rotation_factors(cal).dense(), pose_rotation_covariance(cal))


def test_normal_equations_equal_the_dense_computation(small):
    sim, t, g, cal = small
    rows = check_rows(sim.segments, len(t))
    means, times, _, _, _, Q = pose_statistics(t, g, rows)
    link = np.array([0, 1, 2, 4, 5, 6])  # a gap: segment 3 left out
    model = SegmentModel(
        build_segments(t, g, rows, link, times, "midpoint"),
        "rotations",
        8,
        np.array(cal.rotations),
        Q,
    )
    rng = np.random.default_rng(0)
    x = np.concatenate([(np.eye(3) + 0.01 * rng.normal(size=(3, 3))).ravel(), means.ravel()])
    ev = model.evaluate(x)
    factors = pose_rotation_factors(cal)
    pose = PoseErrors(factors.blocks, factors.factor, False)
    noise = SegmentNoise(model, ev, pose, 1.0)
    # the dense Σ of the segments and the dense Jacobian with every bias column
    B = model.pose_map(ev)
    D = ev.H @ ev.cov_int @ np.transpose(ev.H, (0, 2, 1))
    sigma = B @ factors.dense() @ B.T
    for k in range(len(D)):
        sigma[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] += D[k]
    sigma += 1e-12 * np.max(np.diag(sigma)) * np.eye(len(sigma))
    J = model.dense_jacobian(ev).reshape(len(sigma), -1)
    prior_cov = np.stack([np.diag([1e-6, 2e-6, 3e-6])] * 8)
    prior_inv = np.linalg.inv(prior_cov)
    Si = np.linalg.inv(sigma)
    A = J.T @ Si @ J
    A[9:, 9:] += np.kron(np.eye(8), prior_inv[0])
    grad = J.T @ Si @ ev.r.ravel()
    grad[9:] += (prior_inv[0] @ (x[9:].reshape(8, 3) - means).T).T.ravel()

    ne = NormalSystem(noise, ev, x, means, prior_inv)
    _close(noise.quadratic(ev.r), ev.r.ravel() @ Si @ ev.r.ravel())
    _close(ne.gradient(), grad)
    _close(ne.diagonal(), np.diag(A))
    damping = 1e-2 * np.diag(A)
    _close(ne.step(damping), -np.linalg.solve(A + np.diag(damping), grad))
    info = A[:9, :9] - A[:9, 9:] @ np.linalg.solve(A[9:, 9:], A[9:, :9])
    _close(ne.gain_information(), info)
    L = rng.normal(size=(5, A.shape[0]))
    _close(ne.covariance_of(L), L @ np.linalg.solve(A, L.T))
    blocks = np.stack([sigma[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] for k in range(len(D))])
    _close(noise.blocks, blocks)
    # the gain restricted to some directions: the same with J's gain columns mapped
    basis = np.linalg.qr(rng.normal(size=(9, 7)))[0]
    Jr = np.hstack([J[:, :9] @ basis, J[:, 9:]])
    Ar = Jr.T @ Si @ Jr
    Ar[7:, 7:] += np.kron(np.eye(8), prior_inv[0])
    _close(NormalSystem(noise, ev, x, means, prior_inv, basis).diagonal(), np.diag(Ar))


def test_the_fit_with_the_structure_equals_the_fit_with_the_dense_matrix(small):
    sim, t, g, cal = small
    lines: list[str] = []
    fast = fit_gyro(
        t,
        g,
        sim.segments,
        cal.rotations,
        rotation_cov=pose_rotation_factors(cal),
        on_progress=lines.append,
    )
    dense = fit_gyro(t, g, sim.segments, cal.rotations, rotation_cov=pose_rotation_covariance(cal))
    _close(fast.gain, dense.gain)
    _close(fast.bias, dense.bias)
    _close(fast.covariance.matrix, dense.covariance.matrix)
    assert abs(fast.statistic - dense.statistic) <= 1e-6 * dense.statistic
    assert lines and lines[-1] == f"gyroscope: segment {len(fast.segments)}/{len(fast.segments)}"
    assert all(line.startswith("gyroscope: segment ") for line in lines)


def test_arrow_solves_and_inverts_like_the_dense_matrix():
    rng = np.random.default_rng(1)
    n, q, g = 6, 4, 3
    R = rng.normal(size=(40, n * q + g))
    R[:, : n * q] *= np.kron(np.ones(n), rng.uniform(0.5, 2, q))
    K = R.T @ R + np.eye(n * q + g)
    # keep it block tridiagonal over the n blocks, with a border
    for i in range(n):
        for j in range(n):
            if abs(i - j) > 1:
                K[i * q : (i + 1) * q, j * q : (j + 1) * q] = 0.0
    K += n * np.eye(len(K))  # still positive definite after the cut
    diag = np.stack([K[i * q : (i + 1) * q, i * q : (i + 1) * q] for i in range(n)])
    lower = np.stack([K[(i + 1) * q : (i + 2) * q, i * q : (i + 1) * q] for i in range(n - 1)])
    arrow = Arrow(diag, lower, K[: n * q, n * q :].reshape(n, q, g), K[n * q :, n * q :])
    b = rng.normal(size=(n * q + g, 2))
    u, v = arrow.solve(b[: n * q].reshape(n, q, 2), b[n * q :])
    _close(np.concatenate([u.reshape(-1, 2), v]), np.linalg.solve(K, b))
    X = np.linalg.inv(K[: n * q, : n * q])
    x0, x1, x2 = arrow.band_inverse()
    for i in range(n):
        _close(x0[i], X[i * q : (i + 1) * q, i * q : (i + 1) * q])
        if i + 1 < n:
            _close(x1[i], X[i * q : (i + 1) * q, (i + 1) * q : (i + 2) * q])
        if i + 2 < n:
            _close(x2[i], X[i * q : (i + 1) * q, (i + 2) * q : (i + 3) * q])


def test_blocked_scan_is_the_ordered_product():
    rng = np.random.default_rng(5)
    q = rng.normal(size=(1000, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    want = np.empty_like(q)
    want[0] = q[0]
    for k in range(1, len(q)):
        want[k] = quaternion_multiply(q[k], want[k - 1])
    np.testing.assert_allclose(cumulative_quaternions(q), want, atol=1e-12)
