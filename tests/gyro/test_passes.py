"""The pass over the motion's intervals (chunked, by component, kept) against the plain
interval-by-interval computation it replaces: each segment's turn, integration noise and the
sums of its Jacobian; the same whatever the chunks; kept passes and shared models equal fresh
ones; a model's Jacobian against finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.geometry.rotations import exp_so3
from fieldcal.gyro.data import build_segments, check_rows, pose_statistics
from fieldcal.gyro.integrate import step_parts
from fieldcal.gyro.model import SegmentModel, right_jacobian
from fieldcal.gyro.passes import (
    JACOBIAN,
    NOISE,
    TURNS,
    Integrator,
    chunks_of,
    right_jacobian_columns,
    step_right_jacobian,
)
from fieldcal.simulation.continuous import simulate_continuous

# round-off of a few hundred composed steps, far below any statistical scale of the fit
RTOL = 1e-10


@pytest.fixture(scope="module")
def case():
    sim = simulate_continuous("paper", seed=3, n_poses=7)
    c = sim.columns
    t, g = c["t"], np.column_stack([c["gx"], c["gy"], c["gz"]])
    rows = check_rows(sim.segments, len(t))
    means, times, _, _, _, Q = pose_statistics(t, g, rows)
    data = build_segments(t, g, rows, np.arange(len(rows) - 1), times, "midpoint")
    rng = np.random.default_rng(4)
    M = np.eye(3) + 0.02 * rng.normal(size=(3, 3))
    x = np.concatenate([M.ravel(), (means + 1e-3 * rng.normal(size=means.shape)).ravel()])
    return sim, data, Q, x


def _close(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    assert np.max(np.abs(a - b)) <= RTOL * np.max(np.abs(b)), np.max(np.abs(a - b))


def _reference(data, Q, x):
    """Interval by interval, with rotation matrices (Rodrigues), as the derivation reads."""
    M = x[:9].reshape(3, 3)
    b = x[9:].reshape(-1, 3)
    A = M @ Q @ M.T
    m = len(data.first)
    total = np.empty((m, 3, 3))
    sums = np.zeros((54, m))
    for k in range(m):
        P = np.eye(3)
        i = data.before[k]
        for j in range(data.first[k], data.last[k] + 1):
            lam, dt = data.lam[j], data.dt[j]
            u = data.raw[j] - ((1 - lam) * b[i] + lam * b[i + 1])
            phi = -(M @ u) * dt
            D = dt * P.T @ right_jacobian(phi)
            sums[:9, k] += (dt * P.T @ A @ P).ravel()
            sums[9:36, k] += np.einsum("ca,b->cab", D, u).ravel()
            sums[36:45, k] += (D * (1 - lam)).ravel()
            sums[45:54, k] += (D * lam).ravel()
            P = exp_so3(phi) @ P
        total[k] = P
    return total, sums


@pytest.mark.parametrize("sizes", [None, (300, 70), (1, 1), (300, 70, 4), (10**6, 70, 3)])
def test_pass_is_the_interval_by_interval_computation(case, sizes):
    _, data, Q, x = case
    integrator = Integrator(data, Q)
    if sizes is not None:  # many chunks, parts and blocks: every boundary handled
        integrator._chunks = chunks_of(data, *sizes)
        assert len(integrator._chunks) > 1 or len(data.dt) > 32 * sizes[2]
    done = integrator.run(x, JACOBIAN)
    total, sums = _reference(data, Q, x)
    _close(done.total, total)
    _close(done.sums[:9], sums[:9])
    _close(done.sums[9:36], sums[9:36])
    _close(done.sums[36:], sums[36:])


def test_kept_passes_and_the_scan_of_a_trial_point_give_the_same_numbers(case):
    _, data, Q, x = case
    fresh = Integrator(data, Q).run(x, JACOBIAN)
    integrator = Integrator(data, Q)
    turns = integrator.run(x, TURNS)  # a trial point: its scan kept
    np.testing.assert_array_equal(turns.total, fresh.total)
    full = integrator.run(x, JACOBIAN)  # the scan reused
    np.testing.assert_array_equal(full.sums, fresh.sums)
    assert integrator.run(x, NOISE) is full  # a kept pass serves any lower level
    y = x.copy()
    y[0] += 1e-3
    assert integrator.run(y, TURNS) is not full


def test_a_model_sharing_the_full_models_passes_equals_its_own(case):
    sim, data, Q, x = case
    rows = check_rows(sim.segments, len(sim.columns["t"]))
    c = sim.columns
    t, g = c["t"], np.column_stack([c["gx"], c["gy"], c["gz"]])
    times = pose_statistics(t, g, rows)[1]
    R = np.array(sim.session.truth.rotations)
    full = SegmentModel(data, "rotations", len(rows), R, Q)
    keep = np.array([0, 1, 3, 4, 5])
    picked = build_segments(t, g, rows, keep, times, "midpoint")
    own = SegmentModel(picked, "rotations", len(rows), R, Q)
    shared = SegmentModel(picked, "rotations", len(rows), R, Q, share=(full, keep))
    a, b = own.evaluate(x), shared.evaluate(x)
    for name in ("r", "J_gain", "J_before", "J_after", "total", "cov_int"):
        _close(getattr(b, name), getattr(a, name))
    _close(shared.residuals(x + 1e-4), own.residuals(x + 1e-4))


@pytest.mark.parametrize("method", ["rotations", "gravity"])
def test_the_jacobian_is_the_residuals_derivative(case, method):
    sim, data, Q, x = case
    R = np.array(sim.session.truth.rotations)
    observed = R if method == "rotations" else R[:, :, 2]  # the down direction in the body
    model = SegmentModel(data, method, len(R), observed, Q)
    ev = model.evaluate(x)
    J = model.dense_jacobian(ev).reshape(len(ev.r) * model.d, -1)
    step = 1e-6
    for col in [0, 4, 8, 9, 13, len(x) - 1]:
        e = np.zeros_like(x)
        e[col] = step
        numeric = (model.residuals(x + e) - model.residuals(x - e)).ravel() / (2 * step)
        scale = np.max(np.abs(J[:, col])) + 1e-12
        assert np.max(np.abs(numeric - J[:, col])) <= 1e-5 * scale, col


def test_the_integration_noise_is_the_rotated_noise_density(case):
    _, data, Q, x = case
    done = Integrator(data, Q).run(x, NOISE)
    cov = np.transpose(done.sums[:9].reshape(3, 3, -1), (2, 0, 1))
    # symmetric, positive definite, and its trace the density's times the segment's duration
    _close(cov, np.transpose(cov, (0, 2, 1)))
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    M = x[:9].reshape(3, 3)
    seconds = np.add.reduceat(data.dt, data.first)
    _close(np.trace(cov, axis1=1, axis2=2), np.trace(M @ Q @ M.T) * seconds)


def test_the_steps_right_jacobian_is_the_right_jacobian_of_the_step():
    # from the half angles' sine and cosine, across the series' edge (10⁻³) and large turns
    rng = np.random.default_rng(6)
    angle = np.concatenate([[0.0, 1e-5, 5e-4, 9.99e-4, 1.001e-3, 2e-3], rng.uniform(0, 3, 40)])
    axis = rng.normal(size=(3, len(angle)))
    h = axis / np.linalg.norm(axis, axis=0) * angle
    q, theta2, half_sinc = step_parts(h)
    got = step_right_jacobian(h, theta2, half_sinc, q[0])
    want = right_jacobian_columns(-h)
    assert np.max(np.abs(got - want)) <= 1e-12
    for k in range(len(angle)):
        np.testing.assert_allclose(got[:, :, k], right_jacobian(-h[:, k]), rtol=0, atol=1e-12)


def test_path_lengths_are_the_rates_integrated_fresh_or_from_the_last_pass(case):
    _, data, Q, x = case
    M, b = x[:9].reshape(3, 3), x[9:].reshape(-1, 3)
    lam, pose = data.lam[:, None], data.before[data.seg]
    w = (data.raw - ((1 - lam) * b[pose] + lam * b[pose + 1])) @ M.T
    want = np.add.reduceat(np.linalg.norm(w, axis=1) * data.dt, data.first)
    integrator = Integrator(data, Q)
    _close(integrator.path_length(x), want)
    integrator.run(x, JACOBIAN)  # its steps kept: the same numbers
    _close(integrator.path_length(x), want)
    other = x.copy()
    other[0] *= 1.1  # a pass elsewhere: the kept steps are not used
    integrator.run(other, TURNS)
    _close(integrator.path_length(x), want)
