"""Experiment design: candidate orientations and their words, the information a pose adds, the
criterion, the greedy plan and the first poses (``fieldcal.geometry.orientations``,
``fieldcal.planning.next_pose``, ``docs/methods/planning.md``)."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from _words import AXIS, parse_words
from click.testing import CliRunner
from hypothesis import example, given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import fieldcal
from fieldcal.cli import cli
from fieldcal.errors import InputError
from fieldcal.geometry.orientations import (
    CANDIDATES,
    DOWN_CANDIDATES,
    angle_deg,
    describe,
    orientation_from_vectors,
)
from fieldcal.limits import MOST_PLANNED
from fieldcal.pipeline import fold_axes
from fieldcal.planning.next_pose import (
    PlannedPose,
    Targets,
    first_poses,
    floor,
    plan_poses,
    predict_covariance,
    predicted_line,
    targets_met,
    unreachable,
)
from fieldcal.trust.accuracy import predict_accuracy


# --------------------------------------------------------------------------- words
def test_words_give_back_the_rotation_through_an_independent_parser():
    for c in CANDIDATES:
        down, R = parse_words(c.words)
        assert R is not None
        np.testing.assert_allclose(R, c.rotation, atol=1e-9, err_msg=c.words)
        np.testing.assert_allclose(down, c.down, atol=1e-12)
    for c in DOWN_CANDIDATES:
        down, R = parse_words(c.words)
        assert R is None and c.heading_deg is None
        np.testing.assert_allclose(down, c.down, atol=1e-12)
        np.testing.assert_allclose(c.rotation[:, 2], down, atol=1e-12)


def test_candidates_are_rotations_covering_26_downs_at_4_headings():
    R = np.stack([c.rotation for c in CANDIDATES])
    eye = np.broadcast_to(np.eye(3), R.shape)
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), eye, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    downs = np.stack([c.down for c in DOWN_CANDIDATES])
    nonzero = (np.abs(downs) > 1e-9).sum(axis=1)
    assert sorted(np.bincount(nonzero)[1:].tolist()) == [6, 8, 12]  # faces, corners, edges
    assert len({tuple(np.round(d, 9)) for d in downs}) == 26
    np.testing.assert_allclose(np.linalg.norm(downs, axis=1), 1.0)
    assert len(CANDIDATES) == 104
    # each down direction at the four headings, every rotation distinct (90° apart at least)
    for d in downs:
        same = [c for c in CANDIDATES if np.allclose(c.down, d)]
        assert sorted(c.heading_deg for c in same) == [0.0, 90.0, 180.0, 270.0]
    angles = angle_deg(R[:, None], R[None])
    assert np.all(angles[~np.eye(len(R), dtype=bool)] > 30.0)
    # the named axis' horizontal part points at the stated heading: world direction R^T a_h
    for c in CANDIDATES:
        a = np.eye(3)[AXIS[c.heading_axis[1]]]
        h = c.rotation.T @ (a - (a @ c.down) * c.down)
        # compared on the circle: -1e-15° is 359.999…° after `% 360` on some CPUs
        off = (np.degrees(np.arctan2(h[1], h[0])) - c.heading_deg + 180.0) % 360.0 - 180.0
        assert abs(off) < 1e-9
        assert abs(h[2]) < 1e-12


def test_describe_names_the_nearest_candidate_and_how_far():
    c = CANDIDATES[37]
    small = Rotation.from_rotvec(np.radians(3.0) * np.array([0.6, 0.0, 0.8])).as_matrix()
    assert describe(small @ c.rotation) == c.words
    tilted = Rotation.from_rotvec(np.radians(20.0) * np.array([1.0, 0.0, 0.0])).as_matrix()
    text = describe(tilted @ CANDIDATES[4].rotation)  # +Z down, 20° about body x
    assert text.endswith("(20° away)") or text.endswith("(19° away)"), text
    # heading free: only the down direction counts, whatever the heading
    turned = CANDIDATES[4].rotation @ Rotation.from_euler("z", 123, degrees=True).as_matrix()
    assert (
        describe(turned, heading=False)
        == DOWN_CANDIDATES[1].words
        == ("lying on a face: +X axis pointing straight up")
    )
    with pytest.raises(InputError, match="not a proper rotation"):
        describe(np.diag([1.0, 1.0, -1.0]))


@given(st.integers(0, 2**32 - 1))
@example(233)  # body x 2.8° from vertical: its horizontal part still names north
def test_orientation_from_vectors_is_triad(seed):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=rng).as_matrix()
    dip = np.radians(rng.uniform(-80, 80))
    g = R @ np.array([0.0, 0.0, -1.0]) * rng.uniform(0.5, 2.0)  # the specific force, up
    h = R @ np.array([np.cos(dip), 0.0, np.sin(dip)]) * rng.uniform(0.2, 5.0)
    np.testing.assert_allclose(orientation_from_vectors(g, h), R, atol=1e-9)
    level = orientation_from_vectors(g)  # heading 0: body x's horizontal part points north
    np.testing.assert_allclose(level[:, 2], R[:, 2], atol=1e-12)
    x_world = level.T @ np.eye(3)[0]
    if np.hypot(x_world[0], x_world[1]) > 1e-3:
        assert abs(x_world[1]) < 1e-9 and x_world[0] > 0


def test_orientation_from_vectors_refuses_a_field_along_gravity():
    with pytest.raises(InputError, match="parallel to gravity"):
        orientation_from_vectors([0, 0, 1.0], [0, 0, -2.0])


# --------------------------------------------------------------------------- information
def _balanced(truth, rotations, noise, samples=40):
    """Samples whose means are exactly the model's and whose scatter is the same block of
    zero-mean noise in every pose (so Eq. 7 does not change when poses are added)."""
    out = []
    for name in ("accel", "mag"):
        mu = truth.sensor(name).predict(rotations, truth.reference(name))
        block = np.vstack([noise[name], -noise[name]])
        out.append([m + block for m in mu])
    return out[0], out[1]


@pytest.fixture(scope="module")
def exact():
    """A calibration on exact means (the fit lands on the truth) and the means' generator."""
    s = fieldcal.simulate("paper", seed=5, n_poses=10)
    rng = np.random.default_rng(0)
    noise = {
        n: rng.standard_normal((20, 3)) @ np.linalg.cholesky(s.truth.sensor(n).noise_cov).T
        for n in ("accel", "mag")
    }
    a, m = _balanced(s.truth, s.truth.rotations, noise)
    cal = fieldcal.calibrate(a, m, pose_noise="none", robust=False)
    return s.truth, noise, a, m, cal


def test_a_planned_pose_predicts_the_covariance_calibrate_reports_with_it(exact):
    truth, noise, a, m, cal = exact
    np.testing.assert_allclose(cal.rotations, truth.rotations, atol=1e-8)  # the exact fit
    targets = Targets(dip_deg=0.1)
    plan = plan_poses(cal, 2, targets=targets)
    R = np.stack([p.rotation for p in plan])
    a2, m2 = _balanced(truth, R, noise)
    after = fieldcal.calibrate(a + a2, m + m2, pose_noise="none", robust=False)
    predicted = predict_covariance(cal, R)
    assert predicted.names == after.covariance.names
    scale = np.abs(after.covariance.matrix).max()
    np.testing.assert_allclose(predicted.matrix, after.covariance.matrix, atol=1e-8 * scale)
    assert plan[-1].dip_std_deg == pytest.approx(after.dip_std_deg, rel=1e-7)
    for name in ("tilt_deg", "heading_deg", "accel_norm_rel", "mag_norm_rel"):
        assert getattr(plan[-1].predicted, name) == pytest.approx(
            getattr(after.accuracy, name), rel=1e-7
        )


def _full_covariance(cal, extra):
    """The globals' covariance from the whole (non-Schur) Fisher information, its Jacobian by
    central differences of residuals written here from the model, one more pose at ``extra``."""
    Ra = np.concatenate([cal.rotations, extra[None]])
    n = len(Ra)
    counts = [p["accel_samples"] for p in cal.poses]
    counts.append(int(np.median(counts)))  # the new pose: the median, as plan_poses assumes
    whiten = {}
    for s in ("accel", "mag"):
        sc = cal.sensor(s)
        whiten[s] = [
            np.linalg.inv(np.linalg.cholesky(sc.noise_cov / c + sc.pose_noise_std**2 * np.eye(3)))
            for c in counts
        ]
    sym = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]

    def residuals(theta):
        Ka = np.zeros((3, 3))
        for p, (j, k) in enumerate(sym):
            Ka[j, k] = Ka[k, j] = theta[p]
        ba, Km, bm, dip = theta[6:9], theta[9:18].reshape(3, 3), theta[18:21], theta[21]
        omega = theta[22:].reshape(n, 3)
        R = Rotation.from_rotvec(omega).as_matrix() @ Ra
        g = np.array([0.0, 0.0, -1.0])
        h = np.array([np.cos(dip), 0.0, np.sin(dip)])
        out = []
        for i in range(n):
            out.append(whiten["accel"][i] @ (Ka @ R[i] @ g + ba))
            out.append(whiten["mag"][i] @ (Km @ R[i] @ h + bm))
        return np.concatenate(out)

    Ka = cal.accel.gain
    theta0 = np.concatenate(
        [[Ka[j, k] for j, k in sym], cal.accel.bias, cal.mag.gain.ravel(), cal.mag.bias,
         [np.radians(cal.dip_deg)], np.zeros(3 * n)]
    )  # fmt: skip
    step = 1e-6
    J = np.empty((6 * n, len(theta0)))
    for p in range(len(theta0)):
        e = np.zeros_like(theta0)
        e[p] = step
        J[:, p] = (residuals(theta0 + e) - residuals(theta0 - e)) / (2 * step)
    C = np.linalg.inv(J.T @ J)[:22, :22]
    # to the named parameters: gain entries (both copies of a symmetric one), biases, dip in °
    T = np.zeros((25, 22))
    for p, (j, k) in enumerate(sym):
        T[3 * j + k, p] = T[3 * k + j, p] = 1.0
    T[9:12, 6:9] = np.eye(3)
    T[12:21, 9:18] = np.eye(9)
    T[21:24, 18:21] = np.eye(3)
    T[24, 21] = np.degrees(1.0)
    return T @ C @ T.T


def test_pose_information_equals_the_full_fisher_information():
    s = fieldcal.simulate("paper", seed=11, n_poses=9)
    q = {"accel": 0.002, "mag": 0.003}
    cal = fieldcal.calibrate(s.accel, s.mag, pose_noise=q, robust=False)
    extra = CANDIDATES[61].rotation
    full = _full_covariance(cal, extra)
    schur = predict_covariance(cal, extra[None]).matrix
    np.testing.assert_allclose(schur, full, rtol=1e-5, atol=1e-7 * np.abs(full).max())
    # and without the extra pose, the calibration's own covariance (its Cramér-Rao bound)
    np.testing.assert_allclose(
        predict_covariance(cal, np.zeros((0, 3, 3))).matrix, cal.covariance.matrix, rtol=1e-7,
        atol=1e-9 * np.abs(cal.covariance.matrix).max(),
    )  # fmt: skip


@pytest.mark.parametrize("options", [{}, {"body_frame": "mag"}, {"mag_mirrored": True}])
def test_current_covariance_is_the_reported_one_in_any_gauge_and_units(options):
    """Widened for an estimated pose-level noise, in the user's units (gravity, raw scale), with
    the other sensor fixing the frame, a mirrored magnetometer, or folded axis maps."""
    s = fieldcal.simulate("paper", seed=3)
    raw_a = [x * 4096.0 for x in s.accel]
    cal = fieldcal.calibrate(raw_a, s.mag, gravity=9.80665, field_strength=48.0, **options)
    cals = [cal, fold_axes(cal, np.array([[0, 1.0, 0], [1, 0, 0], [0, 0, -1]]), "+y+x-z")]
    cals.append(fold_axes(cal, -np.eye(3), "gravity", sensor="accel"))
    for c in cals:
        now = predict_covariance(c, np.zeros((0, 3, 3)))
        scale = np.sqrt(np.outer(np.diag(c.covariance.matrix), np.diag(c.covariance.matrix)))
        np.testing.assert_allclose(now.matrix / scale, c.covariance.matrix / scale, atol=1e-7)
        # the batched criterion is trust.accuracy's heading and tilt, in any gauge and units
        plan = plan_poses(c, 1, targets=Targets(heading_deg=1e-6, tilt_deg=1e9))
        assert plan[0].score * 1e-6 == pytest.approx(plan[0].predicted.heading_deg, rel=1e-6)
        plan = plan_poses(c, 1, targets=Targets(heading_deg=1e9, tilt_deg=1e-6))
        assert plan[0].score * 1e-6 == pytest.approx(plan[0].predicted.tilt_deg, rel=1e-6)


# --------------------------------------------------------------------------- the criterion
@pytest.mark.parametrize(
    "goal", [(0.7, 0.3, 0.05), (0.01, 10.0, 10.0), (10.0, 0.01, 10.0), (10.0, 10.0, 0.001)]
)
def test_score_is_the_worst_ratio_of_predicted_error_to_target(goal):
    """Each term made the worst in turn: the batched errors are trust.accuracy's."""
    s = fieldcal.simulate("paper", seed=2)
    cal = fieldcal.calibrate(s.accel, s.mag)
    targets = Targets(*goal)
    for pose in plan_poses(cal, 3, targets=targets):
        worst = max(
            pose.predicted.heading_deg / goal[0],
            pose.predicted.tilt_deg / goal[1],
            pose.dip_std_deg / goal[2],
        )
        assert pose.score == pytest.approx(worst, rel=1e-6)
        assert isinstance(pose, PlannedPose) and pose.words == pose.orientation.words
        assert "worst error/target" in predicted_line(pose)
        assert pose.to_dict()["words"] == pose.words


def test_the_plan_improves_the_criterion_monotonically_without_repeats():
    s = fieldcal.simulate("paper", seed=8)
    cal = fieldcal.calibrate(s.accel, s.mag)
    targets = Targets(heading_deg=0.5, tilt_deg=0.5, dip_deg=0.1)
    now = max(cal.accuracy.heading_deg / 0.5, cal.accuracy.tilt_deg / 0.5, cal.dip_std_deg / 0.1)
    plan = plan_poses(cal, 6, targets=targets)
    scores = [now] + [p.score for p in plan]
    assert all(b < a for a, b in itertools.pairwise(scores)), scores
    assert len({p.words for p in plan}) == 6


def _planar_calibration():
    """The truth of a device whose 12 poses all have the Z axis down, tilted 5-15°."""
    s = fieldcal.simulate("paper", seed=4, n_poses=1, dip_deg=(60.0, 60.0))
    rng = np.random.default_rng(0)
    n = 12
    tilt = np.radians(rng.uniform(5, 15, n))
    az = rng.uniform(0, 2 * np.pi, n)
    yaw = Rotation.from_euler("z", rng.uniform(0, 360, n)[:, None], degrees=True).as_matrix()
    tilts = Rotation.from_rotvec(np.stack([np.cos(az), np.sin(az), 0 * az], 1) * tilt[:, None])
    R = tilts.as_matrix() @ yaw
    rows = tuple({"index": i, "accel_samples": 100, "mag_samples": 100} for i in range(n))
    t = s.truth
    return dataclasses.replace(
        t,
        rotations=R,
        poses=rows,
        accel=dataclasses.replace(t.accel, pose_noise_std=0.001),
        mag=dataclasses.replace(t.mag, pose_noise_std=0.001),
    )


def test_with_every_pose_z_down_the_plan_turns_the_device_over_first():
    cal = _planar_calibration()
    assert np.all(cal.rotations[:, 2, 2] > np.cos(np.radians(16)))  # all Z down
    first = plan_poses(cal, 1)[0]
    assert first.orientation.down[2] <= 0, first.words  # Z level or up: another face/edge
    accel_only = dataclasses.replace(cal, mag=None, magnetic=None)
    first = plan_poses(accel_only, 1)[0]
    assert first.orientation.heading_deg is None and first.orientation.down[2] <= 0


def test_the_planner_beats_random_orientations():
    """Same device, same first 8 poses; 4 more from the planner or at random (5 draws): the
    calibrations fitted on simulated readings report the planner's the better."""
    s = fieldcal.simulate("paper", seed=21, n_poses=1, dip_deg=(65.0, 65.0))
    truth = s.truth
    rng = np.random.default_rng(7)

    def record(R):
        out = []
        for name in ("accel", "mag"):
            sc = truth.sensor(name)
            L = np.linalg.cholesky(sc.noise_cov)
            mu = sc.predict(R, truth.reference(name))
            out.append([m + rng.standard_normal((60, 3)) @ L.T for m in mu])
        return out

    first = np.stack([o.rotation for o in first_poses(None, np.zeros((0, 3)), k=8)])
    a, m = record(first)
    cal = fieldcal.calibrate(a, m)
    targets = Targets(heading_deg=0.5, tilt_deg=0.5, dip_deg=0.1)

    def worst(c):
        return max(c.accuracy.heading_deg / 0.5, c.accuracy.tilt_deg / 0.5, c.dip_std_deg / 0.1)

    plan = np.stack([p.rotation for p in plan_poses(cal, 4, targets=targets)])
    a2, m2 = record(plan)
    planned = worst(fieldcal.calibrate(a + a2, m + m2))
    for _ in range(5):
        R = Rotation.random(4, random_state=rng).as_matrix()
        a3, m3 = record(R)
        assert planned < worst(fieldcal.calibrate(a + a3, m + m3))


# --------------------------------------------------------------------------- one sensor, errors
def test_accelerometer_alone_plans_down_directions_on_tilt_and_relative_errors():
    s = fieldcal.simulate("paper", seed=6, n_poses=12)
    cal = fieldcal.calibrate(s.accel, None)
    plan = plan_poses(cal, 3, targets=Targets(tilt_deg=0.01))
    assert all(p.orientation.heading_deg is None for p in plan)
    assert all(p.orientation in DOWN_CANDIDATES for p in plan)
    assert all(p.dip_std_deg is None and p.predicted.heading_deg is None for p in plan)
    # tilt dominates here: the score is the predicted tilt over its target
    assert plan[0].score >= plan[0].predicted.tilt_deg / 0.01 * (1 - 1e-9)
    assert plan[2].score < plan[0].score
    # no candidate twice until every one has been proposed
    long = plan_poses(cal, 30)
    assert len({p.words for p in long[:26]}) == 26 and long[26].words in {p.words for p in long}


def test_magnetometer_alone_is_refused_in_one_line():
    s = fieldcal.simulate("paper", seed=6, n_poses=12)
    cal = fieldcal.calibrate(None, s.mag)
    with pytest.raises(InputError, match="magnetometer-only") as info:
        plan_poses(cal)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda cal: plan_poses(cal, 0), "k must be a whole number"),
        (lambda cal: plan_poses(cal, True), "k must be a whole number"),
        (lambda cal: plan_poses(cal, 10**6), "k must be at most 100"),  # the CLI's -n cap
        (lambda cal: plan_poses(cal, samples=-3), "samples must be"),
        (lambda cal: plan_poses(cal, targets=(1, 2)), "targets must be"),
        (lambda cal: plan_poses("cal.json"), "needs a fieldcal.Calibration"),
        (lambda cal: predict_covariance(cal, np.ones((2, 3))), "rotations must be"),
        (lambda cal: Targets(heading_deg=0), "heading_deg must be a positive"),
        (lambda cal: Targets(tilt_deg=float("nan")), "tilt_deg must be a positive"),
        (lambda cal: Targets(dip_deg="0.1"), "dip_deg must be a positive"),
        (lambda cal: first_poses([[1.0, 2.0]]), "accel_means must be"),
        (lambda cal: first_poses(np.ones((2, 3)), np.ones((3, 3))), "give both"),
    ],
)
def test_user_errors_are_one_line(call, match):
    s = fieldcal.simulate("paper", seed=1)
    cal = fieldcal.calibrate(s.accel, s.mag)
    with pytest.raises(InputError, match=match) as info:
        call(cal)
    assert "\n" not in str(info.value)


def test_samples_per_pose_come_from_the_calibration_or_must_be_given():
    s = fieldcal.simulate("paper", seed=1)
    cal = fieldcal.calibrate(s.accel, s.mag)
    bare = dataclasses.replace(cal, poses=())
    with pytest.raises(InputError, match="give the samples each pose will average"):
        plan_poses(bare)
    median = int(np.median([p["accel_samples"] for p in cal.poses]))
    assert plan_poses(bare, samples=median)[0].words == plan_poses(cal)[0].words
    # more samples per new pose: a smaller predicted error
    few = plan_poses(cal, samples=5)[0].score
    many = plan_poses(cal, samples=5000)[0].score
    assert many < few


# --------------------------------------------------------------------------- floor, targets
def test_floor_is_the_pose_noise_alone_and_says_when_a_target_is_unreachable():
    s = fieldcal.simulate("paper", seed=9, pose_noise=(0.004, 0.004))
    cal = fieldcal.calibrate(s.accel, s.mag)
    low = floor(cal)
    assert 0 < low.heading_deg < cal.accuracy.heading_deg
    assert 0 < low.tilt_deg < cal.accuracy.tilt_deg
    # many good poses approach the floor, never pass it
    many = np.stack([c.rotation for c in CANDIDATES] * 20)
    cov = predict_covariance(cal, many)
    best = predict_accuracy(dataclasses.replace(cal, covariance=cov))
    assert low.heading_deg < best.heading_deg < 1.2 * low.heading_deg
    message = unreachable(cal, Targets(heading_deg=low.heading_deg / 2, tilt_deg=10))
    assert message is not None and message.startswith("heading target unreachable")
    assert unreachable(cal, Targets(heading_deg=10 * low.heading_deg, tilt_deg=10)) is None


def test_targets_met_reads_verdict_accuracy_and_dip():
    s = fieldcal.simulate("paper", seed=1)
    cal = fieldcal.calibrate(s.accel, s.mag)
    assert cal.verdict.level == "pass"
    acc = cal.accuracy
    loose = Targets(heading_deg=acc.heading_deg * 1.01, tilt_deg=acc.tilt_deg * 1.01)
    assert targets_met(cal, loose)
    assert not targets_met(cal, dataclasses.replace(loose, dip_deg=cal.dip_std_deg * 0.99))
    assert not targets_met(cal, dataclasses.replace(loose, heading_deg=acc.heading_deg * 0.99))
    assert not targets_met(dataclasses.replace(cal, verdict=fieldcal.Verdict("warn")), loose)


# --------------------------------------------------------------------------- first poses
def test_first_poses_start_with_faces_and_skip_what_is_captured():
    joint = first_poses(None, np.zeros((0, 3)), k=8)
    assert [p.kind for p in joint] == ["face"] * 6 + ["corner"] * 2
    assert len({tuple(np.round(p.down, 6)) for p in joint}) == 8
    assert [p.heading_deg for p in joint[:6]] == [0.0, 90.0, 180.0, 270.0, 0.0, 90.0]
    assert all(p.heading_deg is None for p in first_poses(np.zeros((0, 3)), None, k=3))
    # a device with gains, biases (hard iron as large as the field) and noise, held as told
    s = fieldcal.simulate("paper", seed=2, n_poses=1)
    truth = s.truth
    small_bias = dataclasses.replace(truth.accel, bias=[0.03, -0.04, 0.02])
    truth = dataclasses.replace(truth, accel=small_bias)
    R = np.stack([p.rotation for p in joint])
    a, m = (truth.sensor(n).predict(R, truth.reference(n)) for n in ("accel", "mag"))
    for n in range(8):  # each captured prefix gives the next of the starter sequence
        assert first_poses(a[:n], m[:n])[0] == joint[n]
    # poses captured out of order are skipped: the 5th and 2nd taken first
    picked = first_poses(a[[4, 1]], m[[4, 1]], k=3)
    assert [p.down.tolist() for p in picked] == [joint[i].down.tolist() for i in (0, 2, 3)]
    # the starter sequence determines a joint fit at its 8th pose
    cov = predict_covariance(
        dataclasses.replace(truth, rotations=R[:7], poses=tuple(
            {"index": i, "accel_samples": 100, "mag_samples": 100} for i in range(7))),
        R[7:8],
    )  # fmt: skip
    assert np.all(np.isfinite(cov.matrix)) and cov.std("dip_deg") < 1.0


def test_the_library_and_the_command_line_share_one_cap(tmp_path):
    """``plan -n`` and ``plan_poses(cal, k)`` refuse the same k (fieldcal.limits.MOST_PLANNED)."""
    s = fieldcal.simulate("paper", seed=1)
    cal = fieldcal.calibrate(s.accel, s.mag)
    assert len(plan_poses(cal, MOST_PLANNED)) == MOST_PLANNED
    with pytest.raises(InputError, match=f"at most {MOST_PLANNED}"):
        plan_poses(cal, MOST_PLANNED + 1)
    path = tmp_path / "cal.json"
    path.write_text(cal.to_json())
    result = CliRunner().invoke(cli, ["plan", str(path), "-n", str(MOST_PLANNED + 1)])
    assert result.exit_code == 2 and f"1<=x<={MOST_PLANNED}" in result.output
