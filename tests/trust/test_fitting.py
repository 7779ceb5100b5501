"""The trust path on sessions with a known truth and on real recordings: pose-level noise,
rejection of a disturbed pose with the right sensor, the verdict, split-half error bars.

Fast and seeded; the slow studies behind these checks are in ``benchmarks/trust.py``
(``docs/benchmarks.md``, section trust). Tolerances come from the noise: the estimated pose
noise within 3 of its standard errors, disturbances of 50 standard deviations of a pose mean.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import fieldcal
from fieldcal.trust.accuracy import predict_accuracy

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import _real_sets as real

N_POSES = 20


def _white(session):
    """Per-axis noise of a pose mean, sqrt(tr Σ / 3 / mean count), per sensor."""
    count = float(np.mean(session.counts))
    return {
        s: float(np.sqrt(np.trace(session.truth.sensor(s).noise_cov) / 3 / count))
        for s in ("accel", "mag")
    }


def _with_pose_noise(seed, n_poses, level):
    base = fieldcal.simulate("paper", seed=seed, n_poses=n_poses)
    white = _white(base)
    q = (level * white["accel"], level * white["mag"])
    return fieldcal.simulate("paper", seed=seed, n_poses=n_poses, pose_noise=q), q


def _calibrate(accel, mag, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fieldcal.calibrate(accel, mag, **options)


def _disturbed(seed, sensor, pose, size):
    """A clean session with pose ``pose``'s ``sensor`` samples offset by ``size`` standard
    deviations of that pose mean, along the sensor's field at that pose."""
    s = fieldcal.simulate("paper", seed=seed, n_poses=N_POSES)
    sc = s.truth.sensor(sensor)
    d = sc.gain @ s.truth.rotations[pose] @ s.truth.reference(sensor)
    d /= np.linalg.norm(d)
    sigma = np.sqrt(d @ sc.noise_cov @ d / s.counts[pose])
    samples = {name: list(getattr(s, name)) for name in ("accel", "mag")}
    samples[sensor][pose] = samples[sensor][pose] + size * sigma * d
    return samples["accel"], samples["mag"]


# --------------------------------------------------------------------------- pose noise
@pytest.mark.parametrize("seed", [11, 12])
def test_pose_noise_of_six_times_white_is_recovered_within_three_standard_errors(seed):
    s, q = _with_pose_noise(seed, 30, 6.0)
    cal = _calibrate(s.accel, s.mag)
    for name, q_true in zip(("accel", "mag"), q, strict=True):
        sc = cal.sensor(name)
        assert sc.pose_noise_std_se is not None and sc.pose_noise_std_se > 0
        assert abs(sc.pose_noise_std - q_true) <= 3 * sc.pose_noise_std_se, (
            name,
            sc.pose_noise_std,
            q_true,
            sc.pose_noise_std_se,
        )
    assert cal.options["pose_noise"] == {"accel": "estimated", "mag": "estimated"}


def test_pose_noise_none_gives_zero_and_a_user_value_is_kept():
    s, _ = _with_pose_noise(13, N_POSES, 6.0)
    none = _calibrate(s.accel, s.mag, pose_noise="none")
    assert none.accel.pose_noise_std == 0.0 and none.mag.pose_noise_std == 0.0
    given = _calibrate(s.accel, s.mag, pose_noise=0.01)
    assert given.accel.pose_noise_std == pytest.approx(0.01, rel=1e-12)
    assert given.mag.pose_noise_std == pytest.approx(0.01, rel=1e-12)
    assert given.options["pose_noise"] == {"accel": "given", "mag": "given"}
    mixed = _calibrate(s.accel, s.mag, pose_noise={"accel": 0.02})
    assert mixed.accel.pose_noise_std == pytest.approx(0.02, rel=1e-12)
    assert mixed.options["pose_noise"] == {"accel": "given", "mag": "estimated"}
    assert mixed.mag.pose_noise_std > 0


# --------------------------------------------------------------------------- rejection
def test_clean_session_passes_without_rejection():
    s = fieldcal.simulate("paper", seed=21, n_poses=N_POSES)
    cal = _calibrate(s.accel, s.mag)
    assert cal.rejected == ()
    assert cal.verdict.level == "pass", cal.verdict.reasons


def test_magnetic_disturbance_of_one_pose_is_rejected_as_mag():
    accel, mag = _disturbed(22, "mag", pose=7, size=50)
    cal = _calibrate(accel, mag)
    assert [(r.index, r.sensor) for r in cal.rejected] == [(7, "mag")]
    assert cal.rejected[0].p_value < 0.01 / (2 * N_POSES)
    assert "magnetic disturbance" in cal.rejected[0].reason
    # a dropped pose warns, naming it
    assert cal.verdict.level == "warn"
    assert [r.code for r in cal.verdict.reasons if r.level != "note"] == ["rejected"]
    assert cal.n_poses == N_POSES - 1 and 7 not in [p["index"] for p in cal.poses]


def test_bump_of_one_pose_is_rejected_as_accel():
    accel, mag = _disturbed(23, "accel", pose=3, size=50)
    cal = _calibrate(accel, mag)
    assert [r.index for r in cal.rejected] == [3]
    assert cal.rejected[0].sensor in ("accel", "both")
    assert "moved or bumped" in cal.rejected[0].reason
    assert cal.verdict.level == "warn"


def test_without_robust_the_disturbed_pose_stays_and_inflates_the_pose_noise():
    accel, mag = _disturbed(22, "mag", pose=7, size=50)
    robust = _calibrate(accel, mag)
    plain = _calibrate(accel, mag, robust=False)
    assert plain.rejected == () and plain.n_poses == N_POSES
    assert plain.mag.pose_noise_std > 3 * max(
        robust.mag.pose_noise_std, robust.mag.pose_noise_std_se
    )


# --------------------------------------------------------------------------- verdict
def test_verdict_fails_when_the_magnetometer_is_a_copy_of_the_accelerometer():
    s = fieldcal.simulate("paper", seed=24, n_poses=N_POSES)
    rng = np.random.default_rng(24)
    # the accelerometer's columns read again as the magnetometer's: scaled, offset, own noise
    mag = [2.0 * a + 0.3 + rng.normal(0.0, 1e-3, a.shape) for a in s.accel]
    cal = _calibrate(s.accel, mag)
    assert cal.verdict.level == "fail"
    assert "same_sensor" in cal.verdict.codes


# --------------------------------------------------------------------------- real data
@pytest.mark.parametrize(("folder", "name"), [("sap6", "sap6-HC"), ("ck-explorer", "ck-acc_log")])
def test_split_half_z_on_real_recordings(shared_data, folder, name):
    root = shared_data(folder).parent
    data = real.load(name, root)
    half = real.split_half(data)
    print(f"{name}: split-half RMS z {half.rms_z:.2f}", {k: round(v, 2) for k, v in half.z.items()})
    # RMS of 3-7 standard normal z's: 0.3-2.5 holds with probability above 0.98
    assert 0.3 <= half.rms_z <= 2.5
    full = _calibrate(data.accel, data.mag)
    assert full.verdict.level == "pass", full.verdict.reasons


def test_predicted_heading_error_does_not_depend_on_either_sensors_units():
    """The heading error's finite differences step in each sensor's own units: on a
    calibration in raw units whose magnetometer counts are 10^4 times larger (or smaller)
    than the accelerometer's, the prediction is the one made in unit scale (one shared step
    gave 1e-4 off)."""
    session = fieldcal.simulate("paper", seed=2)
    for factor in (1e4, 1e-4):
        counts = fieldcal.calibrate(session.accel, [m * factor for m in session.mag])
        again = predict_accuracy(counts).heading_deg
        assert again == pytest.approx(counts.accuracy.heading_deg, rel=1e-9)
