"""The gyroscope stage: exact integration, maximum-likelihood gain and bias, what the turns
determine, the simulated gyroscope's truth, and real recordings."""

from __future__ import annotations

import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import fieldcal
from fieldcal.errors import InputError
from fieldcal.geometry.rotations import exp_so3, hat, random_rotations
from fieldcal.gyro import GAIN_NAMES, effective_time, fit_gyro, integrate, rotation_vector
from fieldcal.likelihood.cramer_rao import pose_rotation_covariance
from fieldcal.simulation.continuous import simulate_continuous
from fieldcal.simulation.device import MEMS, Device

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from _real_sets import imucal_turns  # the loader the benchmark uses too

UP = np.array([0.0, 0.0, -1.0])  # the accelerometer's reference (specific force) in NED


def _gyro(sim):
    c = sim.columns
    return c["t"], np.column_stack([c["gx"], c["gy"], c["gz"]])


def _calibrate(accel, mag):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fieldcal.calibrate(accel, mag)


def _board_log(rotations, *, seed=0, still=1.5, move=1.2, **options):
    """A Device put through ``rotations`` (drawn frame): still, turn, still, ..."""
    device = Device("paper", seed=seed, **options)
    parts, poses, row = [], [], 0
    for i, R in enumerate(rotations):
        s = device.still(R, still)
        parts.append(s)
        poses.append((row, row + s.n))
        row += s.n
        if i + 1 < len(rotations):
            m = device.move(R, rotations[i + 1], move)
            parts.append(m)
            row += m.n
    t = np.concatenate([p.t for p in parts])
    gyro = np.concatenate([p.gyro for p in parts])
    return device, t, gyro, poses


def _within(fit, truth, k=4.0):
    """Every determined entry within k of the fit's own standard errors."""
    z_gain = (fit.gain - truth.gain) / fit.gain_std
    z_bias = (fit.bias - truth.bias) / fit.bias_std
    determined = np.array([n in fit.observable for n in GAIN_NAMES]).reshape(3, 3)
    assert np.all(np.abs(z_gain[determined]) < k), z_gain
    assert np.all(np.abs(z_bias) < k), z_bias


# ----------------------------------------------------------------------------- integration
@pytest.mark.parametrize("hold", ["midpoint", "previous"])
def test_constant_rate_about_a_fixed_axis_is_exact_on_irregular_timestamps(hold):
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.002, 0.03, 800))  # jitter over a factor of 15
    w = np.array([0.7, -2.1, 1.3])  # rad/s, about 5 turns in all
    R = integrate(t, np.tile(w, (len(t), 1)), hold=hold)
    np.testing.assert_allclose(R, exp_so3(-w * (t[-1] - t[0])), atol=1e-12)
    every = integrate(t, np.tile(w, (len(t), 1)), cumulative=True, hold=hold)
    np.testing.assert_allclose(every, exp_so3(-w[None] * (t - t[0])[:, None]), atol=1e-12)
    # world→body: a vector fixed in the world, seen from the body, turns the other way
    assert np.allclose(every[1] @ every[0].T, exp_so3(-w * (t[1] - t[0])), atol=1e-14)


def test_coning_motion_converges_to_the_closed_form_at_second_order():
    """R(t) = A B Aᵀ, A = exp(Ωt [e_z]×), B = exp(β [e_x]×): the axis of a β turn sweeps a
    cone. dR/dt = −[ω]× R gives ω = Ω (R e_z − e_z), body frame."""
    omega, beta, T = 3.0, 0.4, 2.0
    ez = np.array([0.0, 0.0, 1.0])

    def R(t):  # noqa: N802 - the rotation, named as in the docstring
        A = exp_so3(np.outer(omega * np.atleast_1d(t), ez))
        return A @ exp_so3(beta * np.array([1.0, 0.0, 0.0])) @ np.transpose(A, (0, 2, 1))

    errors = []
    for n in (200, 400, 800):
        t = np.linspace(0.0, T, n + 1)
        w = omega * (R(t) @ ez - ez)
        got = integrate(t, w)
        want = R(T)[0] @ R(0.0)[0].T
        errors.append(np.linalg.norm(rotation_vector(got.T @ want)))
    assert errors[-1] < 1e-5
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3.5) & (ratios < 4.5)), ratios  # halving the step quarters it


def test_bursts_share_the_gap_and_time_going_back_is_refused():
    t = np.array([0.0, 0.0, 0.0, 0.3, 0.4, 0.4])
    # the last burst shares the median step (0.2 s) after it
    np.testing.assert_allclose(effective_time(t), [0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    w = np.tile([0.0, 0.0, 1.0], (6, 1))
    np.testing.assert_allclose(integrate(t, w), exp_so3(-np.array([0, 0, 0.5])), atol=1e-14)
    with pytest.raises(InputError, match=r"time goes backwards at row 3.*--split-on-reset"):
        integrate([0.0, 0.1, 0.2, 0.05], np.zeros((4, 3)))
    # less than a step back is jitter: the row shares the time before it, then is spread
    np.testing.assert_allclose(effective_time([0.0, 0.2, 0.1, 0.4]), [0.0, 0.2, 0.3, 0.4])


def test_rotation_vector_inverts_exp_up_to_half_a_turn():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(500, 3))
    v *= (rng.uniform(0, np.pi, 500) / np.linalg.norm(v, axis=1))[:, None]
    v[0] = [np.pi - 1e-9, 0.0, 0.0]
    v[1] = [1e-13, 0.0, 0.0]
    got = rotation_vector(exp_so3(v))
    np.testing.assert_allclose(exp_so3(got), exp_so3(v), atol=1e-12)
    np.testing.assert_allclose(got[1:], v[1:], atol=1e-9)


# ----------------------------------------------------------------------------- simulation truth
def test_simulated_gyroscope_reads_the_body_frame_rate_with_its_drawn_truth():
    """With an ideal, noise-free gyroscope the integrated readings between two poses are the
    turn R_{i+1} R_iᵀ of the drawn rotations (the sign of dR/dt = −[ω]× R)."""
    sim = simulate_continuous("paper", seed=4, n_poses=6, ideal_gyro=True, gyro_noise=0.0)
    t, g = _gyro(sim)
    R = sim.session.drawn["rotations"]
    for i, ((_, stop), (start, _)) in enumerate(
        zip(sim.segments[:-1], sim.segments[1:], strict=True)
    ):
        turn = integrate(t[stop - 1 : start + 1], g[stop - 1 : start + 1])
        # the geodesic is sampled at mid-steps: the midpoint sum of a raised cosine is exact
        # to (π/2m)²/6 of the angle
        err = np.linalg.norm(rotation_vector(turn.T @ R[i + 1] @ R[i].T))
        assert err < 1e-3
    assert np.array_equal(sim.gyro_drawn.gain, np.eye(3)) and not np.any(sim.gyro_drawn.bias)
    # in fieldcal's gauge an ideal gyroscope's gain is the rotation into that frame
    gain = sim.gyro_truth.gain
    np.testing.assert_allclose(gain @ gain.T, np.eye(3), atol=1e-12)


def test_default_gyroscope_is_a_mems_part_drawn_from_its_own_stream():
    a = simulate_continuous("paper", seed=7, n_poses=4)
    b = simulate_continuous("paper", seed=7, n_poses=4, ideal_gyro=True)
    # the other columns do not move with the gyroscope's truth
    assert all(np.array_equal(a.columns[k], b.columns[k]) for k in ("ax", "my", "t"))
    d = a.gyro_drawn
    scale = np.linalg.svd(d.gain, compute_uv=False)
    assert np.all(np.abs(scale - 1) < MEMS["scale"] + 3 * MEMS["cross_axis"])
    assert np.all(np.abs(d.bias) <= MEMS["bias"]) and np.any(d.bias != 0)
    assert d.noise_std == pytest.approx(0.005)
    assert simulate_continuous("paper", seed=7, n_poses=4, rate=400.0).gyro_drawn.noise_std == (
        pytest.approx(0.01)
    )
    assert Device(seed=7).gyro_drawn == d  # the same stream: the same part for one seed
    # in fieldcal's gauge the gain takes the accelerometer's polar rotation
    U = fieldcal.geometry.frames.orthogonal_polar_factor(a.session.drawn["accel_gain"])
    np.testing.assert_allclose(a.gyro_truth.gain, d.gain @ U.T)


# ----------------------------------------------------------------------------- estimation
@pytest.fixture(scope="module")
def session():
    sim = simulate_continuous("paper", seed=11, n_poses=12, samples=(200, 300))
    cal = _calibrate(sim.session.accel, sim.session.mag)
    assert not cal.rejected
    return sim, cal, pose_rotation_covariance(cal)


def test_rotations_recover_gain_and_bias_within_their_standard_errors(session):
    sim, cal, cov = session
    t, g = _gyro(sim)
    fit = fit_gyro(t, g, sim.segments, cal.rotations, rotation_cov=cov)
    _within(fit, sim.gyro_truth)
    assert fit.method == "rotations" and len(fit.observable) == 12 and not fit.rejected
    assert fit.gain_std.max() < 0.01 and fit.bias_std.max() < 5e-4
    # 11 segments, 33 residuals, 9 gain entries: χ²(24) at the optimum
    assert fit.dof == 24 and fit.p_value > 1e-3 and fit.widening == 1.0
    assert fit.drift_p_value > 1e-3  # a constant bias
    np.testing.assert_allclose(
        fit.correct(fit.gain @ [0.1, -0.2, 0.3] + fit.bias), [0.1, -0.2, 0.3]
    )
    noise = sim.gyro_truth.noise_std**2
    assert np.all(np.abs(np.diag(fit.noise_cov) / noise - 1) < 0.1)


def test_the_fit_is_the_same_in_any_raw_unit(session):
    sim, cal, cov = session
    t, g = _gyro(sim)
    one = fit_gyro(t, g, sim.segments, cal.rotations, rotation_cov=cov)
    kilo = fit_gyro(t, 1000.0 * g, sim.segments, cal.rotations, rotation_cov=cov)
    np.testing.assert_allclose(kilo.gain, 1000.0 * one.gain, rtol=1e-9)
    np.testing.assert_allclose(kilo.bias, 1000.0 * one.bias, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(kilo.covariance.matrix, 1e6 * one.covariance.matrix, rtol=1e-7)


def test_without_orientation_covariance_it_is_estimated(session):
    sim, cal, _ = session
    t, g = _gyro(sim)
    fit = fit_gyro(t, g, sim.segments, cal.rotations)
    _within(fit, sim.gyro_truth)
    assert fit.statistic == pytest.approx(fit.dof, rel=1e-3)  # s² makes χ² its dof


def test_accelerometer_only_recovers_the_gain_from_gravity_directions(session):
    sim, _, _ = session
    cal = _calibrate(sim.session.accel, None)
    g_body = cal.correct_accel(np.array([a.mean(0) for a in sim.session.accel]))
    C = pose_rotation_covariance(cal)  # the two tilt angles of each pose
    X = np.zeros_like(C)
    for i, u in enumerate(g_body):
        X[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = -hat(u)
    t, g = _gyro(sim)
    fit = fit_gyro(t, g, sim.segments, gravity_body=g_body, gravity_cov=X @ C @ X.T)
    assert fit.method == "gravity" and len(fit.observable) == 12
    _within(fit, sim.gyro_truth)
    assert np.median(fit.segment_residual_deg) < 1.0


def _turns_about_x_and_y(n=10, seed=1):
    rng = np.random.default_rng(seed)
    R = [random_rotations(1, rng)[0]]
    for i in range(n - 1):  # R ← exp([a]×) R: a turn about body axis x or y
        R.append(exp_so3(np.eye(3)[i % 2] * rng.uniform(0.6, 1.5) * rng.choice([-1, 1])) @ R[-1])
    return np.array(R)


@pytest.mark.parametrize("path", ["rotations", "gravity"])
def test_turns_never_about_z_leave_its_column_free_and_say_so(path):
    R = _turns_about_x_and_y()
    device, t, g, poses = _board_log(R)
    small = np.eye(3 * len(R)) * 1e-6
    given = (
        {"rotations": R, "rotation_cov": small}
        if path == "rotations"
        else {"gravity_body": R @ UP, "gravity_cov": small}
    )
    z_column = "gyro.gain[0,2], gyro.gain[1,2], gyro.gain[2,2]"
    with pytest.raises(InputError, match=rf"do not determine {re.escape(z_column)} .*axis z"):
        fit_gyro(t, g, poses, **given)
    fit = fit_gyro(t, g, poses, **given, allow_partial=True)
    assert set(GAIN_NAMES) - set(fit.observable) == {f"gyro.gain[{j},2]" for j in range(3)}
    assert "gyro.gain[2,2]" not in fit.covariance.names
    _within(fit, device.gyro_drawn)  # R is in the drawn frame: compare with the drawn part
    # the free column stays at the start's (a scaled identity): no prediction changes with it
    assert np.all(np.abs(fit.gain[:2, 2]) < 1e-4) and abs(fit.gain[2, 2] - 1) < 0.1


def test_turns_about_the_vertical_tell_gravity_nothing():
    rng = np.random.default_rng(2)
    R = [exp_so3(np.array([0.3, 0.2, 0.0]))]
    for _ in range(7):  # R ← R exp([θ e_down]×): a turn about the world's vertical
        R.append(R[-1] @ exp_so3(np.array([0.0, 0.0, rng.uniform(0.5, 1.5)])))
    R = np.array(R)
    _, t, g, poses = _board_log(R)
    with pytest.raises(InputError, match=r"gain\[0,0\].*gain\[2,2\] \(no turn tilts the device"):
        fit_gyro(t, g, poses, gravity_body=R @ UP)
    # the same turns seen as full rotations determine everything
    fit = fit_gyro(t, g, poses, R, rotation_cov=np.eye(3 * len(R)) * 1e-6, allow_partial=True)
    assert len(fit.observable) < 12  # about one axis only: still not all of the gain


def test_bias_drift_is_measured_and_called_significant():
    sim = simulate_continuous("paper", seed=5, n_poses=10, samples=(200, 300), gyro_drift=5e-4)
    t, g = _gyro(sim)
    R = sim.session.truth.rotations
    fit = fit_gyro(t, g, sim.segments, R, rotation_cov=np.eye(3 * len(R)) * 1e-6)
    drift = sim.gyro_drawn.drift
    assert np.linalg.norm(drift) > 3e-4  # this seed draws a drift well above the noise
    assert fit.drift_p_value < 1e-6
    assert np.all(np.abs(fit.drift_rate - drift) < 5e-5)
    z = (fit.gain - sim.gyro_truth.gain) / fit.gain_std  # the drift interpolated, not a bias
    assert np.all(np.abs(z) < 4), z


def test_bad_input_is_refused_in_one_line(session):
    sim, cal, cov = session
    t, g = _gyro(sim)
    with pytest.raises(InputError, match=r"2 motion segment.*at least 3"):
        fit_gyro(t, g, sim.segments[:3], cal.rotations[:3])
    with pytest.raises(InputError, match="time goes backwards"):
        fit_gyro(t[::-1], g, sim.segments, cal.rotations)
    with pytest.raises(InputError, match="give the poses' rotations"):
        fit_gyro(t, g, sim.segments)
    with pytest.raises(InputError, match="rotations must have shape"):
        fit_gyro(t, g, sim.segments, cal.rotations[:-1])
    clipped = np.clip(g, -0.5, 0.5)  # a ±0.5 rad/s part: the turns go past it
    with pytest.raises(InputError, match=r"saturates on axis .* turn more slowly"):
        fit_gyro(t, clipped, sim.segments, cal.rotations, rotation_cov=cov)
    with pytest.raises(InputError, match="saturates on axis"):
        fit_gyro(t, g, sim.segments, cal.rotations, rotation_cov=cov, full_scale=0.6)


def test_a_segment_the_gyroscope_never_saw_is_rejected(session):
    """A jump in the log (a logger paused between two poses): the fitted turn happened, the
    gyroscope saw none of it. The segment is dropped, the rest recovers the truth."""
    sim, cal, cov = session
    t, g = _gyro(sim)
    g = g.copy()
    (_, stop), (start, _) = sim.segments[4], sim.segments[5]
    g[stop:start] = g[stop - 1]  # the turn replaced by a still reading
    fit = fit_gyro(t, g, sim.segments, cal.rotations, rotation_cov=cov)
    assert fit.rejected == ((stop - 1, start),) and fit.rejected_residual_deg[0] > 20
    _within(fit, sim.gyro_truth)


# ----------------------------------------------------------------------------- real data
def test_imucal_full_turns_give_the_ferraris_scale(shared_data):
    """imucal's annotated session: three turns of 360° on a table (about x, y, z, each axis
    up). A full turn ends where it began, so the rotations are the identity and only the
    scale along each turn's axis is determined; imucal's Ferraris fit divides the integrated
    raw rate by the known 2π instead, which also gives the axes' misalignment."""
    pytest.importorskip("pandas", reason="pandas (the pandas extra) not installed")
    turns = imucal_turns(shared_data("imucal").parent)
    fit, ref = turns.fit(), turns.reference
    ferraris = np.abs(np.diag(np.array(ref["K_g"]) @ np.array(ref["R_g"]))) * np.degrees(1.0)
    assert {"gyro.gain[0,0]", "gyro.gain[1,1]"} <= set(fit.observable)
    assert "gyro.gain[0,1]" not in fit.observable  # a full turn hides its axis' tilt
    np.testing.assert_allclose(np.diag(fit.gain)[:2], ferraris[:2], rtol=2e-3)
    np.testing.assert_allclose(fit.bias, ref["b_g"], atol=1.0)  # counts; noise ~3 per sample
