"""method="ellipsoid": the CK-Explorer seed's ellipsoid fit and alignment, faithful and hardened.

Tolerances are derived from the simulated noise in each test; every RNG is seeded.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import fieldcal
from fieldcal.geometry.quadrics import (
    algebraic_fit,
    li_griffiths_fit,
    quadric_from_coefficients,
    reverse_triangular_factor,
)
from fieldcal.geometry.rotations import exp_so3, random_rotations, rotation_angle_deg
from fieldcal.methods import dot_alignment
from fieldcal.methods import ellipsoid as method
from fieldcal.metrics import reconstruction_error

L_TRUE = np.array([[1.10, 0.0, 0.0], [0.05, 0.90, 0.0], [-0.03, 0.08, 1.05]])
C_TRUE = np.array([0.3, -0.2, 0.5])


def _unit(n: int, rng: np.random.Generator) -> np.ndarray:
    u = rng.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _ellipsoid_samples(L, c, n, sigma, rng):
    """Raw readings whose correction ``L (s − c)`` lies on the unit sphere, plus noise."""
    return np.linalg.solve(L, _unit(n, rng).T).T + c + sigma * rng.normal(size=(n, 3))


def _ring(seed: int = 0, sigma: float = 0.02) -> np.ndarray:
    """Poor coverage: a magnetometer turned about the vertical only (latitudes 55-65°)."""
    rng = np.random.default_rng(seed)
    lat = np.radians(rng.uniform(55.0, 65.0, 400))
    lon = rng.uniform(0.0, 2 * np.pi, 400)
    ring = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], 1)
    return ring + sigma * rng.normal(size=ring.shape)


def _paired_unit_vectors(n, dip_deg, misalignment, sigma, rng):
    """Accelerometer and magnetometer directions in n random poses; the magnetometer's axes
    are rotated by ``misalignment`` (so ``misalignment @ m`` is in the accelerometer's axes)."""
    R = random_rotations(n, rng)
    dip = np.radians(dip_deg)
    a = R @ np.array([0.0, 0.0, -1.0]) + sigma * rng.normal(size=(n, 3))
    m = (R @ np.array([np.cos(dip), 0.0, np.sin(dip)])) @ misalignment
    return a, m + sigma * rng.normal(size=(n, 3))


# =========================================================================== faithful core
@pytest.mark.parametrize("conditioned", [False, True])
def test_algebraic_fit_recovers_a_known_lower_triangular_factor_and_centre(conditioned):
    rng = np.random.default_rng(1)
    n, sigma = 2000, 1e-3
    quadric = algebraic_fit(
        _ellipsoid_samples(L_TRUE, C_TRUE, n, sigma, rng), conditioned=conditioned
    )
    L = reverse_triangular_factor(quadric.shape)
    # each estimate has a standard error of order sigma / sqrt(n) = 2.2e-5; allow 10 of them
    tol = 10 * sigma / np.sqrt(n)
    assert np.max(np.abs(quadric.center - C_TRUE)) < tol
    assert np.max(np.abs(L - L_TRUE)) < tol
    assert np.sum(quadric.coefficients[:3]) == pytest.approx(-3.0)  # trace constraint


def test_eq_9_to_12_from_coefficients():
    M = L_TRUE.T @ L_TRUE
    # (x − c)ᵀ M (x − c) = 1 written as Eq. 8 with an arbitrary scale m = 1/κ = 0.37
    V = 0.37 * M
    v = np.array([V[0, 0], V[1, 1], V[2, 2], V[0, 1], V[0, 2], V[1, 2], *(-V @ C_TRUE)])
    v = np.append(v, C_TRUE @ V @ C_TRUE - 0.37)
    quadric = quadric_from_coefficients(v)
    assert quadric.kappa == pytest.approx(0.37)  # Eq. 11
    np.testing.assert_allclose(quadric.center, C_TRUE, atol=1e-12)
    np.testing.assert_allclose(quadric.shape, M, atol=1e-12)  # Eq. 12


def test_reverse_triangular_factor_is_eq_13_not_cholesky():
    M = L_TRUE.T @ L_TRUE
    L = reverse_triangular_factor(M)
    np.testing.assert_allclose(L, L_TRUE, atol=1e-12)
    np.testing.assert_allclose(L.T @ L, M, atol=1e-12)
    C = np.linalg.cholesky(M)  # M = C Cᵀ: the other factorisation
    assert np.max(np.abs(C - L)) > 1e-2
    assert np.max(np.abs(C.T @ C - M)) > 1e-2


@given(
    arrays(np.float64, (3, 3), elements=st.floats(-2.0, 2.0)),
    st.floats(0.05, 2.0),
)
def test_reverse_triangular_factor_round_trips_any_spd_matrix(A, ridge):
    M = A.T @ A + ridge * np.eye(3)
    L = reverse_triangular_factor(M)
    assert np.all(np.triu(L, 1) == 0) and np.all(np.diag(L) > 0)
    np.testing.assert_allclose(L.T @ L, M, rtol=0, atol=1e-10 * np.linalg.norm(M))


def test_reverse_triangular_factor_of_an_indefinite_matrix_is_nan_like_the_seed():
    assert np.isnan(reverse_triangular_factor(np.diag([1.0, -1.0, 1.0]))).any()


def test_stereographic_projection_eq_18_to_24():
    identity = method.stereographic_to_quaternion([1.0, 0.0, 0.0])
    np.testing.assert_allclose(identity, [1.0, 0.0, 0.0, 0.0])
    rng = np.random.default_rng(2)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    back = method.stereographic_to_quaternion(method.quaternion_to_stereographic(q))
    np.testing.assert_allclose(back, q, atol=1e-12)


def test_hardened_residual_has_an_exact_analytic_jacobian():
    rng = np.random.default_rng(3)
    a, m = _unit(30, rng), _unit(30, rng)
    R0 = exp_so3(np.array([0.3, -0.2, 0.9]))
    rows = dot_alignment._outer_rows(a, m)
    residual, jacobian = dot_alignment._residual_hardened(rows, R0)
    x = np.array([0.8, 0.3, -0.4, 1.2])
    numeric = dot_alignment._forward_difference(residual)(x)
    np.testing.assert_allclose(jacobian(x), numeric, atol=1e-6)


# =========================================================================== failure modes
def test_poor_coverage_hyperboloid_nan_in_faithful_li_griffiths_when_hardened():
    samples, sigma = _ring(), 0.02
    with pytest.warns(method.NotAnEllipsoidWarning, match="not an ellipsoid"):
        faithful = method.fit_ellipsoid(samples, faithful=True)
    assert not faithful.is_ellipsoid and np.isnan(faithful.correction).any()
    with (
        pytest.warns(method.NotAnEllipsoidWarning),
        pytest.raises(ValueError, match=r"faithful fit .* not an ellipsoid"),
    ):
        fieldcal.calibrate(samples, None, method="ellipsoid", faithful=True)

    with pytest.warns(method.NotAnEllipsoidWarning, match="Li & Griffiths"):
        hardened = method.fit_ellipsoid(samples)
    assert hardened.fallback_used and hardened.is_ellipsoid
    assert np.all(np.isfinite(hardened.correction))
    # distance of each sample from the fitted surface, raw units: the noise, sigma, for the
    # true sphere; the fallback is not the geometric optimum (1.27 sigma measured), allow 2
    v = hardened.correct(samples)
    norm = np.linalg.norm(v, axis=1)
    distance = (norm - 1) / norm * np.linalg.norm(samples - hardened.center, axis=1)
    assert np.sqrt(np.mean(distance**2)) < 2 * sigma
    with pytest.warns(method.NotAnEllipsoidWarning):
        cal = fieldcal.calibrate(samples, None, method="ellipsoid")
    assert "li-griffiths" in cal.message
    np.testing.assert_allclose(cal.accel.bias, hardened.center)


def test_a_150_degree_misalignment_traps_the_faithful_start_not_the_hardened():
    rng = np.random.default_rng(1)
    axis = np.array([0.83, -0.23, 0.51])
    R_true = exp_so3(axis / np.linalg.norm(axis) * np.radians(150.0))
    dip, sigma, n = 17.0, 0.01, 500
    a, m = _paired_unit_vectors(n, dip, R_true, sigma, rng)
    beta_true = -np.sin(np.radians(dip))

    faithful = method.align(a, m, faithful=True)
    assert faithful.converged  # the solver says "done" ...
    assert rotation_angle_deg(faithful.rotation.T @ R_true) > 90  # ... at a wrong minimum
    assert abs(faithful.beta - beta_true) > 0.2

    hardened = method.align(a, m)
    # the residual per pair has std ~ sqrt(2) sigma; beta's standard error is that / sqrt(n)
    # = 6e-4 and the rotation's about 0.06°: allow 8 of them
    assert abs(hardened.beta - beta_true) < 8 * np.sqrt(2) * sigma / np.sqrt(n)
    assert rotation_angle_deg(hardened.rotation.T @ R_true) < 0.5
    assert hardened.misalignment_deg == pytest.approx(150.0, abs=0.5)


def test_large_raw_counts_break_the_normal_equations_not_the_conditioned_fit():
    # a 24-bit converter near the end of its range: offset ~8e6 counts, field radius 1e4 counts,
    # noise 2 counts, rounded. (At 4e6 how far the normal equations degrade depends on the BLAS
    # kernels: 2x the floor on one machine, over 10x on another; at 8e6 it is 20-40x on both.)
    rng = np.random.default_rng(0)
    radius, sigma = 1e4, 2.0
    center = 8e6 * np.array([0.8, -0.6, 1.0])
    samples = np.round(_ellipsoid_samples(L_TRUE / radius, center, 3000, sigma, rng))
    # the calibrated norm cannot scatter less than the noise (with rounding) over the radius
    floor = np.hypot(sigma, np.sqrt(1 / 12)) / radius
    spread = {}
    for faithful in (True, False):
        fit = method.fit_ellipsoid(samples, faithful=faithful)
        spread[faithful] = np.std(np.linalg.norm(fit.correct(samples), axis=1))
    assert spread[False] < 1.2 * floor
    assert spread[True] > 10 * floor


def test_hardened_beta_is_a_cosine_and_a_failed_solver_is_an_error(monkeypatch):
    rng = np.random.default_rng(4)
    a, m = _paired_unit_vectors(200, 60.0, np.eye(3), 0.05, rng)
    result = method.align(a, m)
    assert -1 <= result.beta <= 1 and result.converged and result.status > 0

    real = dot_alignment.least_squares  # the alignment (Eq. 16) lives there

    def stalled(*args, **kwargs):
        out = real(*args, **kwargs)
        out.status, out.message = 0, "The maximum number of function evaluations is exceeded."
        return out

    monkeypatch.setattr(dot_alignment, "least_squares", stalled)
    with pytest.raises(method.AlignmentError, match="did not converge") as info:
        method.align(a, m)
    assert isinstance(info.value, ValueError) and "\n" not in str(info.value)


# =========================================================================== calibrate()
@pytest.fixture(scope="module")
def session():
    return fieldcal.simulate("paper", seed=3)


def _deltas(cal, session):
    ta, tm = session.truth.predicted_means()
    pa, pm = cal.predicted_means()
    return (
        reconstruction_error(ta, pa, session.truth.accel.noise_cov, session.counts),
        reconstruction_error(tm, pm, session.truth.mag.noise_cov, session.counts),
    )


@pytest.mark.parametrize("seed", [0, 3, 7])
def test_calibrate_predicts_the_true_means(seed):
    session = fieldcal.simulate("paper", seed=seed)
    cal = fieldcal.calibrate(session.accel, session.mag, method="ellipsoid")
    assert cal.method == "ellipsoid" and cal.converged and cal.iterations > 0
    # δ (Eq. 19) is in units of one sample's noise σ. Fitted on raw samples the algebraic
    # ellipsoid's radius is biased by about tr(Σ)/(2r), up to ~0.5 σ here (0.12-1.1 over
    # seeds 0-7, accel and mag): allow 1.5.
    assert max(_deltas(cal, session)) < 1.5
    # On the pose means that bias is gone; δ 0.05-0.1 over seeds 0-7: allow 0.2.
    means = fieldcal.calibrate(session.accel, session.mag, method="ellipsoid", fit_on="pose_means")
    assert max(_deltas(means, session)) < 0.2
    assert means.diagnostics.dof == 3 * 15 - 22


def test_corrections_invert_the_forward_model_and_share_one_frame(session):
    cal = fieldcal.calibrate(session.accel, session.mag, method="ellipsoid", fit_on="pose_means")
    rng = np.random.default_rng(5)
    v = rng.normal(size=(20, 3))
    np.testing.assert_allclose(cal.correct_accel(cal.accel.distort(v)), v, atol=1e-12)
    np.testing.assert_allclose(cal.correct_mag(cal.mag.distort(v)), v, atol=1e-12)
    stats = fieldcal.summarize(session.accel, session.mag)
    a = cal.correct_accel(stats.accel.means)
    m = cal.correct_mag(stats.mag.means)
    # corrected pose means are the rotated fields: |.| = 1 and a·m = −sin(dip), to within a
    # few times the noise of a mean (σ ≤ 0.15, Δ ≥ 400: ≤ 0.0075)
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1, atol=0.03)
    np.testing.assert_allclose(np.linalg.norm(m, axis=1), 1, atol=0.03)
    dot = np.sum(a * m, axis=1) / np.linalg.norm(a, axis=1) / np.linalg.norm(m, axis=1)
    np.testing.assert_allclose(dot, -np.sin(np.radians(cal.dip_deg)), atol=0.03)
    np.testing.assert_allclose(cal.dip_deg, session.truth.dip_deg, atol=1.0)
    # the gauge: symmetric accelerometer gain, rotations are rotations
    np.testing.assert_allclose(cal.accel.gain, cal.accel.gain.T, atol=1e-12)
    np.testing.assert_allclose(
        cal.rotations @ cal.rotations.transpose(0, 2, 1), np.eye(3)[None].repeat(15, 0), atol=1e-12
    )


def test_calibration_fields_are_filled(session):
    cal = fieldcal.calibrate(session.accel, session.mag, method="ellipsoid")
    assert cal.rotations.shape == (15, 3, 3)
    np.testing.assert_allclose(cal.gravity, [0, 0, -1])
    assert cal.accel.noise_source == "scatter" and cal.mag.noise_source == "scatter"
    stats = fieldcal.summarize(session.accel, session.mag)
    np.testing.assert_allclose(cal.accel.noise_cov, stats.accel.cov)
    assert np.isfinite(cal.cost) and cal.cost == pytest.approx(cal.diagnostics.statistic)
    assert len(cal.poses) == 15 and "alignment" in cal.message
    expected = {
        "faithful": False,
        "inclination_deg": None,
        "fit_on": "samples",
        "body_frame": "accel",
        "input": "poses",
        "mag_mirrored": False,
    }
    assert {k: cal.options[k] for k in expected} == expected
    again = fieldcal.Calibration.from_json(cal.to_json())
    np.testing.assert_array_equal(again.mag.gain, cal.mag.gain)
    json.loads(cal.to_json())


def test_continuous_input_gives_the_same_sensors_without_poses(session):
    poses = fieldcal.calibrate(session.accel, session.mag, method="ellipsoid")
    cont = fieldcal.calibrate(np.vstack(session.accel), np.vstack(session.mag), method="ellipsoid")
    # same samples, same pairs: the same fit (the gauge depends only on the accel gain)
    np.testing.assert_allclose(cont.accel.gain, poses.accel.gain, atol=1e-10)
    np.testing.assert_allclose(cont.mag.gain, poses.mag.gain, atol=1e-10)
    np.testing.assert_allclose(cont.mag.bias, poses.mag.bias, atol=1e-10)
    assert cont.rotations.shape == (0, 3, 3) and np.isnan(cont.cost) and cont.poses == ()
    assert cont.accel.noise_source == "residuals"
    # isotropic noise from the radial residuals: of the order of the true per-axis variance
    true_var = np.trace(session.truth.accel.noise_cov) / 3
    assert 0.3 * true_var < cont.accel.noise_cov[0, 0] < 3 * true_var
    assert cont.options["input"] == "continuous"


def test_gravity_and_field_strength_scale_the_gains(session):
    unit = fieldcal.calibrate(session.accel, session.mag, method="ellipsoid")
    phys = fieldcal.calibrate(
        session.accel, session.mag, method="ellipsoid", gravity=9.80665, field_strength=48.5
    )
    np.testing.assert_allclose(phys.accel.gain, unit.accel.gain / 9.80665, rtol=1e-12)
    np.testing.assert_allclose(phys.mag.gain, unit.mag.gain / 48.5, rtol=1e-12)
    assert phys.gravity_norm == pytest.approx(9.80665) and phys.field_strength == pytest.approx(
        48.5
    )
    for a, b in zip(phys.predicted_means(), unit.predicted_means(), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)


def test_one_sensor_alone(session):
    acc = fieldcal.calibrate(session.accel, None, method="ellipsoid")
    assert acc.mag is None and acc.magnetic is None and acc.rotations.shape == (15, 3, 3)
    assert acc.diagnostics.dof == 15 - 9 and acc.iterations == 0
    stats = fieldcal.summarize(session.accel)
    down = acc.correct_accel(stats.accel.means)
    body_g = acc.rotations @ acc.gravity
    np.testing.assert_allclose(
        body_g, down / np.linalg.norm(down, axis=1, keepdims=True), atol=1e-12
    )
    mag = fieldcal.calibrate(None, session.mag, method="ellipsoid")
    assert mag.accel is None and mag.gravity is None and mag.mag is not None
    assert "dip not observable" in mag.message and mag.dip_deg is None


def test_body_frame_mag_makes_the_magnetometer_gain_symmetric(session):
    cal = fieldcal.calibrate(session.accel, session.mag, method="ellipsoid", body_frame="mag")
    np.testing.assert_allclose(cal.mag.gain, cal.mag.gain.T, atol=1e-12)


def test_faithful_calibrate_agrees_with_hardened_on_good_data(session):
    faithful = fieldcal.calibrate(session.accel, session.mag, method="ellipsoid", faithful=True)
    hardened = fieldcal.calibrate(session.accel, session.mag, method="ellipsoid")
    assert faithful.options["faithful"] is True
    np.testing.assert_allclose(faithful.accel.gain, hardened.accel.gain, atol=1e-8)
    # the alignments differ only by Eq. 16's weighting (raw norms vs unit vectors)
    assert abs(faithful.dip_deg - hardened.dip_deg) < 0.5


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"gamma": 1e-4}, r"unknown option\(s\) 'gamma' for method 'ellipsoid'"),
        ({"fit_on": "medians"}, "fit_on must be"),
        ({"inclination_deg": 120.0}, "inclination_deg must be a number in"),
        ({"faithful": "yes"}, "faithful must be True or False"),
    ],
)
def test_bad_options_are_one_line_errors(session, kwargs, message):
    with pytest.raises(ValueError, match=message) as info:
        fieldcal.calibrate(session.accel, session.mag, method="ellipsoid", **kwargs)
    assert "\n" not in str(info.value)


def test_bad_inputs_say_what_is_needed(session):
    with pytest.raises(ValueError, match="needs at least 9"):
        fieldcal.calibrate(session.accel[:8], session.mag[:8], method="ellipsoid")
    rng = np.random.default_rng(6)
    with pytest.raises(ValueError, match=r"at least 10 are needed .*9 free parameters"):
        fieldcal.calibrate(rng.normal(size=(9, 3)), None, method="ellipsoid")
    with pytest.raises(ValueError, match="pair the two sensors"):
        fieldcal.calibrate(rng.normal(size=(50, 3)), rng.normal(size=(40, 3)), method="ellipsoid")
    bad = rng.normal(size=(50, 3))
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        fieldcal.calibrate(bad, None, method="ellipsoid")
    with pytest.raises(ValueError, match="needs per-pose input"):
        fieldcal.calibrate(rng.normal(size=(50, 3)), None, method="ellipsoid", fit_on="pose_means")
    with pytest.raises(ValueError, match="rank-deficient"):
        method.fit_ellipsoid(np.column_stack([rng.normal(size=(50, 2)), np.zeros(50)]))


def test_li_griffiths_agrees_with_the_algebraic_fit_on_good_coverage():
    rng = np.random.default_rng(7)
    samples = _ellipsoid_samples(L_TRUE, C_TRUE, 2000, 1e-3, rng)
    lg, alg = li_griffiths_fit(samples), algebraic_fit(samples)
    # both are consistent estimators; they differ by a few standard errors (2.2e-5)
    np.testing.assert_allclose(lg.center, alg.center, atol=2e-4)
    np.testing.assert_allclose(lg.shape, alg.shape, atol=2e-3)


def test_weights_equal_repeated_points():
    rng = np.random.default_rng(8)
    points = _ellipsoid_samples(L_TRUE, C_TRUE, 30, 1e-2, rng)
    counts = rng.integers(1, 5, 30)
    weighted = algebraic_fit(points, counts.astype(float))
    repeated = algebraic_fit(np.repeat(points, counts, axis=0))
    np.testing.assert_allclose(weighted.shape, repeated.shape, atol=1e-10)
    np.testing.assert_allclose(weighted.center, repeated.center, atol=1e-10)


# =========================================================================== real data
def _csv(path):
    return np.loadtxt(path, delimiter=",", skiprows=1)


def test_ck_explorer_accelerometer_is_calibrated_to_unit_norm(shared_data):
    acc = _csv(shared_data("ck-explorer") / "acc_log.csv")
    # the sensor's noise: median over 50-sample windows of the per-axis standard deviation
    # (the log is quasi-static), about 0.0028 g
    noise = float(np.median(acc.reshape(-1, 50, 3).std(axis=1, ddof=1)))
    for faithful in (True, False):
        fit = method.fit_ellipsoid(acc, faithful=faithful)
        norm = np.linalg.norm(fit.correct(acc), axis=1)
        assert norm.mean() == pytest.approx(1.0, abs=1e-3)
        # the residual motion adds to the noise: measured 0.0039 g = 1.4 noise; allow 2
        assert norm.std() < 2 * noise
        assert fit.fit_method == "algebraic"


def test_ck_explorer_alignment_matches_the_reference(shared_data):
    data = _csv(shared_data("ck-explorer") / "acc_mag_log.csv")
    accel, mag = data[:, :3], data[:, 3:]
    faithful = method.align(
        accel, method.fit_ellipsoid(mag, faithful=True).correct(mag), faithful=True
    )
    # The reference (README: an independent numpy/scipy re-implementation) prints
    # beta ~= 0.3064, theta ~= 72.2°, q ~= [0.99975, -0.00088, -0.01405, 0.01741], i.e. 2.56°.
    # Two LM implementations stop at their own tolerance (relative 1e-8 here): allow the last
    # printed digit, 5e-4 in beta (0.03° in theta) and 2e-4 per quaternion component.
    assert faithful.converged and faithful.start == "identity"
    assert faithful.beta == pytest.approx(0.3064, abs=5e-4)
    assert faithful.theta_deg == pytest.approx(72.16, abs=0.05)
    np.testing.assert_allclose(
        faithful.quaternion, [0.99975, -0.00088, -0.01405, 0.01741], atol=2e-4
    )
    assert faithful.misalignment_deg == pytest.approx(2.57, abs=0.05)
    assert faithful.dip_deg == pytest.approx(faithful.theta_deg - 90.0)

    hardened = method.align(accel, method.fit_ellipsoid(mag).correct(mag))
    # unit vectors weight the pairs slightly differently (the accelerometer's norm varies by
    # 4 % with motion): the same answer to 2e-3 in beta and 0.1° in rotation
    assert hardened.beta == pytest.approx(faithful.beta, abs=2e-3)
    assert rotation_angle_deg(hardened.rotation.T @ faithful.rotation) < 0.1


def test_ck_explorer_through_calibrate(shared_data):
    data = _csv(shared_data("ck-explorer") / "acc_mag_log.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # good coverage: no fallback warning
        cal = fieldcal.calibrate(data[:, :3], data[:, 3:], method="ellipsoid")
    # the accelerometer columns are already calibrated, so fitting them again barely moves
    # beta: dip = theta − 90° ≈ −17.8°
    assert cal.dip_deg == pytest.approx(-17.8, abs=0.1)
    assert cal.converged and cal.rotations.shape == (0, 3, 3)
