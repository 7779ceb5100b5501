"""Thousands of one-sample poses (``poses="samples"`` on a slow log, issue 33 item 6): the short
cuts that make them fast — every flagged pose dropped in one round, the noise and the starts
first found on a subset, Levenberg–Marquardt's extrapolated steps and its stop at a settled J —
give the result the one-at-a-time, every-pose computation gives, within a small fraction of
the standard errors, and still drop the disturbed rows."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from fieldcal.geometry.frames import GRAVITY, magnetic_reference
from fieldcal.geometry.rotations import exp_so3, random_rotations
from fieldcal.likelihood import levenberg
from fieldcal.logs.inputs import read_log
from fieldcal.methods import mle
from fieldcal.pipeline import LogSettings, run_log
from fieldcal.trust import fitting

ROWS = 900
BUMPS = np.arange(100, ROWS, 300)  # three rows knocked: 0.3 g on the accelerometer


def _slow_log(seed: int) -> dict[str, np.ndarray]:
    """A board turned slowly (20°/s about a wandering axis, 3 rows/s), accelerometer and
    magnetometer with a few % of gain error, biases, white noise and three bumps."""
    rng = np.random.default_rng(seed)
    axis = np.cumsum(rng.normal(0.0, 0.2, (ROWS, 3)), axis=0) + rng.normal(size=3)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    steps = exp_so3(-axis * np.radians(20.0) / 3.0)
    R = np.empty((ROWS, 3, 3))
    R[0] = random_rotations(1, rng)[0]
    for k in range(1, ROWS):
        R[k] = steps[k - 1] @ R[k - 1]
    Ka = np.eye(3) + rng.uniform(-0.03, 0.03, (3, 3))
    Km = np.eye(3) + rng.uniform(-0.1, 0.1, (3, 3))
    accel = R @ GRAVITY @ Ka.T + rng.uniform(-0.05, 0.05, 3)
    mag = R @ magnetic_reference(np.radians(60.0)) @ Km.T + rng.uniform(-0.5, 0.5, 3)
    accel += 0.003 * rng.standard_normal((ROWS, 3))
    mag += 0.01 * rng.standard_normal((ROWS, 3))
    accel[BUMPS] += 0.3 * rng.standard_normal((len(BUMPS), 3))
    columns = {}
    for prefix, data in (("a", accel), ("m", mag)):
        for letter, column in zip("xyz", data.T, strict=True):
            columns[prefix + letter] = column
    return columns


def _calibrate(columns: dict[str, np.ndarray]):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_log(read_log(columns), LogSettings.of({}, poses="samples", gyro=False))


def _parameters(cal) -> tuple[np.ndarray, np.ndarray]:
    names = cal.covariance.names
    values = []
    for name in names:
        if name == "dip_deg":
            values.append(cal.dip_deg)
            continue
        sensor, rest = name.split(".")
        part, where = rest.rstrip("]").split("[")
        index = tuple(int(i) for i in where.split(","))
        values.append(np.asarray(getattr(cal.sensor(sensor), part))[index])
    return np.array(values), np.sqrt(np.diag(cal.covariance.matrix))


@pytest.fixture(scope="module")
def log() -> dict[str, np.ndarray]:
    return _slow_log(5)


def test_the_short_cuts_give_the_full_computations_result(log, monkeypatch):
    with monkeypatch.context() as m:  # the thousands' short cuts at 900 poses (a fast test)
        m.setattr(fitting, "SUBSET_NOISE_POSES", 600)
        m.setattr(mle, "COLD_SUBSET_POSES", 600)
        m.setattr(levenberg, "SETTLED_POSES", 600)
        fast = _calibrate(log).calibration
    with monkeypatch.context() as m:  # one pose dropped per round, every pose from the start
        m.setattr(fitting, "MANY_POSES", 10**9)
        m.setattr(fitting, "SUBSET_NOISE_POSES", 10**9)
        m.setattr(mle, "COLD_SUBSET_POSES", 10**9)
        m.setattr(mle, "SUBSET_POSES", 10**9)
        m.setattr(levenberg, "SETTLED_POSES", 10**9)
        full = _calibrate(log).calibration
    x_fast, _ = _parameters(fast)
    x_full, se = _parameters(full)
    assert np.max(np.abs(x_fast - x_full) / se) < 0.05
    assert np.allclose(
        np.sqrt(np.diag(fast.covariance.matrix)), se, rtol=0.02
    )  # the error bars too
    dropped = {r.index for r in fast.rejected}
    assert set(BUMPS.tolist()) <= dropped  # every bump found in the rounds of many drops
    # the borderline poses may differ, the bumps never
    assert len(dropped ^ {r.index for r in full.rejected}) <= 2


def test_many_poses_drop_every_flagged_pose_in_one_round():
    p_min = np.array([0.5, 1e-9, 0.2, 1e-12, 1e-7] + [0.9] * 300)
    flagged = p_min < 1e-6
    np.testing.assert_array_equal(fitting._worst(p_min, flagged, 10), [3, 1, 4])  # worst first
    np.testing.assert_array_equal(fitting._worst(p_min, flagged, 2), [3, 1])  # at most spare
    few = p_min[:5]
    np.testing.assert_array_equal(fitting._worst(few, few < 1e-6, 10), [3])  # few: the worst
