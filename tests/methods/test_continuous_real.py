"""The continuous estimator on real recordings: BROAD trials 04 and 01 (a 9-axis IMU turned by
hand, with and without breaks, optical motion capture as ground truth; ../shared/data/broad, its
README).

The vendor calibrated these logs already (not perfectly: its magnetometer keeps about 5 % of
soft iron), so they are de-calibrated here with a known gain ``D`` and bias ``c`` per sensor.
The fit must recover ``D K₀`` and ``D b₀ + c``, where ``K₀, b₀`` is what the vendor's readings
still need — for the magnetometer measured independently by an ellipsoid fit of the vendor's
readings (:func:`fieldcal.geometry.quadrics.family_fit`), for the accelerometer and the
gyroscope the identity and zero — within the fit's error bars plus ``ALLOWANCE`` (the
oracles' own errors). The fitted trajectory must agree with the motion capture. Skipped with the
reason when the recordings are absent.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_data_dir

from fieldcal.geometry.quadrics import family_fit
from fieldcal.geometry.rotations import project_to_so3, quaternion_to_matrix, rotation_angle_deg
from fieldcal.methods.continuous import fit_continuous
from fieldcal.methods.continuous.uncertainty import NAMES
from fieldcal.trust.accuracy import predict_accuracy

#: Beyond the fit's error bars, the oracles' errors: what the vendor's accelerometer (m/s²)
#: and gyroscope (rad/s) keep, the ellipsoid's error (µT); relative gain (K Kᵀ, Frobenius).
#: The lab's field is not uniform: after either calibration (ellipsoid or this fit) the
#: magnetometer's norm still spreads by 2.3 %, and the two disagree on K Kᵀ by 4 %.
ALLOWANCE = {"accel": 0.15, "mag": 1.0, "gyro": 0.012}
GAIN_ALLOWANCE = {"accel": 0.02, "mag": 0.06, "gyro": 0.02}
#: Every third sample (95 Hz): the hand's motion is far below 47 Hz, and the test stays fast.
DECIMATE = 3

D_ACCEL = np.array([[1.02, 0.01, -0.005], [0.01, 0.98, 0.008], [-0.005, 0.008, 1.01]])
C_ACCEL = np.array([0.3, -0.2, 0.15])
D_MAG = np.array([[1.1, 0.05, 0.02], [-0.03, 0.95, 0.04], [0.01, -0.02, 1.05]])
C_MAG = np.array([20.0, -15.0, 10.0])
D_GYRO = np.array([[1.03, 0.01, 0.0], [-0.01, 0.98, 0.005], [0.0, 0.0, 1.01]])
C_GYRO = np.array([0.02, -0.01, 0.015])


@pytest.fixture(scope="module")
def trial():
    folder = shared_data_dir("broad")
    data = np.genfromtxt(
        folder / "04_undisturbed_slow_rotation_with_breaks_A.csv", delimiter=",", names=True
    )[::DECIMATE]

    def cols(*names):
        return np.column_stack([data[n] for n in names])

    raw = {
        "accel": cols("ax", "ay", "az") @ D_ACCEL.T + C_ACCEL,
        "mag": cols("mx", "my", "mz") @ D_MAG.T + C_MAG,
        "gyro": cols("gx", "gy", "gz") @ D_GYRO.T + C_GYRO,
    }
    cal = fit_continuous(data["t"], raw["accel"], raw["mag"], raw["gyro"], gravity=9.81)
    vendor = {
        # the hand's acceleration blurs an ellipsoid of the accelerometer's readings more than
        # the vendor's calibration errs: the published values are the oracle, within ALLOWANCE
        "accel": (np.eye(3), np.zeros(3)),
        "mag": family_fit(cols("mx", "my", "mz"), np.ones(len(data))),
        "gyro": (np.eye(3), np.zeros(3)),  # rad/s as published
    }
    return data, cal, vendor


DECAL = {"accel": (D_ACCEL, C_ACCEL), "mag": (D_MAG, C_MAG), "gyro": (D_GYRO, C_GYRO)}


def test_biases_recovered(trial):
    _, cal, vendor = trial
    for sensor, (D, c) in DECAL.items():
        fitted = getattr(cal, sensor)
        expected = D @ vendor[sensor][1] + c
        limit = 5 * fitted.bias_std + ALLOWANCE[sensor]
        assert np.all(np.abs(fitted.bias - expected) < limit), (sensor, fitted.bias, expected)


def test_gains_recovered_up_to_the_body_frame(trial):
    _, cal, vendor = trial
    # K Kᵀ does not depend on the body frame's choice; the field magnitudes are free
    for sensor, (D, _) in DECAL.items():
        K = np.asarray(getattr(cal, sensor).gain)
        expected = D @ vendor[sensor][0]
        KKt, EEt = K @ K.T, expected @ expected.T
        scale = np.trace(KKt) / np.trace(EEt)
        rel = np.linalg.norm(KKt / scale - EEt) / np.linalg.norm(EEt)
        assert rel < GAIN_ALLOWANCE[sensor], (sensor, rel)
    # the gyroscope's scale is absolute (rad/s): no scale free
    Kg = np.asarray(cal.gyro.gain)
    assert np.linalg.norm(Kg @ Kg.T - D_GYRO @ D_GYRO.T) / 3 < GAIN_ALLOWANCE["gyro"]


def test_trajectory_agrees_with_motion_capture(trial):
    data, cal, _ = trial
    step = round(cal.options["epoch_seconds"] / np.median(np.diff(data["t"])))
    R = np.asarray(cal.rotations)
    q = np.column_stack([data[k] for k in ("qw", "qx", "qy", "qz")])[::step][: len(R)]
    seen = np.all(np.isfinite(q), axis=1)
    # motion-capture frame ← body ← NED: one constant rotation when both are right
    W = quaternion_to_matrix(q[seen]) @ R[seen]
    err = rotation_angle_deg(np.swapaxes(W, 1, 2) @ project_to_so3(W.mean(axis=0)))
    assert np.median(err) < 2.0
    assert np.quantile(err, 0.95) < 5.0
    assert _settled(cal)


def _settled(cal) -> bool:
    """What the estimator's own findings would fail: not converged, a group undetermined by
    the motion or left unsettled by the fit (the accuracy rules are the trust path's)."""
    motion = cal.findings.motion
    return cal.converged and not (motion.undetermined or motion.unsettled or motion.lacking)


def _values(cal) -> np.ndarray:
    out = []
    for sensor in ("accel", "mag"):
        out += [*getattr(cal, sensor).gain.ravel(), *getattr(cal, sensor).bias]
    out.append(cal.dip_deg)
    out += [*cal.gyro.gain.ravel(), *cal.gyro.bias]
    return np.array(out)


def test_split_halves_agree_within_their_error_bars():
    """Issue 23 item 2 on real data: the two halves of trial 01 (slow turns, no rests, 199 s),
    each calibrated alone, differ by (a − b)/sqrt(σa² + σb²) with an RMS over the 37
    parameters within 0.5–2 (1.36 at every sixth sample, 1.39 at every third; with the
    Cramér–Rao bound alone, without the sandwich's widening for correlated residuals, 3.7 and
    6.2). Every sixth sample (48 Hz) keeps the test to a few seconds."""
    folder = shared_data_dir("broad")
    path = folder / "01_undisturbed_slow_rotation_A.csv"
    data = np.genfromtxt(path, delimiter=",", names=True)[::6]
    half = len(data) // 2
    cals = []
    for part in (data[:half], data[half:]):
        cols = [np.column_stack([part[p + a] for a in "xyz"]) for p in "amg"]
        cal = fit_continuous(part["t"], *cols, gravity=9.81)
        assert _settled(cal), cal.findings.motion
        cals.append(cal)
    a, b = cals
    sd = np.hypot(a.covariance.stds(list(NAMES)), b.covariance.stds(list(NAMES)))
    z = (_values(a) - _values(b)) / sd
    rms = float(np.sqrt(np.mean(z**2)))
    assert 0.5 <= rms <= 2.0, (rms, np.round(z, 1))


def test_icm20948_without_time_stamps_measures_its_gyroscope_misfit():
    """ICM-20948 session 3 (../shared/data/icm20948-deadtomgc): no time stamps, a loop that
    sleeps 30 ms (about 28 Hz), the accelerometer's low-pass filter on. At the nominal rate the
    gyroscope's factors misfit far beyond its raw white noise (0.004 rad/s); trusting that
    noise, Levenberg–Marquardt diverged. The fit measures the misfit instead, converges, and
    its accelerometer's bias lands within 0.005 g of the upstream ellipsoid fit's centre (not a
    ground truth: the README), well inside the body's acceleration."""
    folder = shared_data_dir("icm20948-deadtomgc")
    d = np.genfromtxt(folder / "derived" / "session3.csv", delimiter=",", names=True)
    accel = np.column_stack([d["ax_g"], d["ay_g"], d["az_g"]])
    gyro = np.radians(np.column_stack([d["gx_dps"], d["gy_dps"], d["gz_dps"]]))
    mag = np.column_stack([d["mx_rawdiv10"], -d["my_rawdiv10"], -d["mz_rawdiv10"]])  # README
    cal = fit_continuous(np.arange(len(d)) / 28.0, accel, mag, gyro, gravity=1.0)
    assert _settled(cal), cal.findings.motion
    assert cal.options["noise"]["gyro_rate_std"] > 20 * 0.004
    upstream = np.array([0.00670413, 0.00555252, 0.0131])  # accelCenter3
    assert np.all(np.abs(cal.accel.bias - upstream) < 0.005), cal.accel.bias


def test_allowances_widen_the_tilt_error_bar_to_the_verticals_error(trial):
    """Trial 04 (slow turns with breaks) fitted with ``allowances=True`` (Eq. C6a–C6b): on the
    quasi-static samples (rate < 0.5 rad/s, ||a| − g| < 0.3 m/s²) the calibrated
    accelerometer's direction is within 0.8° RMS of the vendor's and within 3 times the
    predicted tilt error (0.66° against 0.26° seen on the knots, not yet the issue's 2;
    against 0.13° without:
    the trajectory's tilt follows the lab's field and the hand's acceleration into the
    accelerometer's bias, which the allowances count in the error bar)."""
    data, _, _ = trial

    def cols(*names):
        return np.column_stack([data[n] for n in names])

    vendor = cols("ax", "ay", "az")
    raw = [vendor @ D_ACCEL.T + C_ACCEL, cols("mx", "my", "mz") @ D_MAG.T + C_MAG]
    gyro = cols("gx", "gy", "gz") @ D_GYRO.T + C_GYRO
    cal = fit_continuous(data["t"], *raw, gyro, gravity=9.81, allowances=True)
    assert cal.options["allowances"] is True
    still = (np.linalg.norm(cols("gx", "gy", "gz"), axis=1) < 0.5) & (
        np.abs(np.linalg.norm(vendor, axis=1) - 9.81) < 0.3
    )
    ours = cal.correct_accel(vendor[still] @ D_ACCEL.T + C_ACCEL)
    cos = np.sum(ours * vendor[still], 1) / np.linalg.norm(ours, axis=1)
    cos /= np.linalg.norm(vendor[still], axis=1)
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    assert still.sum() > 1000
    rms = float(np.sqrt(np.mean(angle**2)))
    assert rms < 0.8
    predicted = predict_accuracy(cal).tilt_deg
    assert predicted is not None
    assert rms < 3.0 * predicted, (rms, predicted)
