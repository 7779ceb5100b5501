"""Temperature terms with the conventions the pipeline folds back (:func:`fieldcal.pipeline.
fold_axes`): a magnetometer axis map and an accelerometer that reports gravity. The result on
the log as logged equals the fit on the log mapped beforehand, with the coefficients folded
(``c_k → Pᵀ c_k``) and their error bars carried."""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.geometry.frames import parse_axes
from fieldcal.simulation.warmup import simulate_warmup_log

MAP = "+y-x-z"


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """The same warm-up written twice: as a board with a rotated magnetometer and a
    gravity-reporting accelerometer logs it, and mapped beforehand."""
    w = simulate_warmup_log(seed=2, n_poses=18, span=20.0)
    folder = tmp_path_factory.mktemp("fold")
    mapped = folder / "mapped.csv"
    w.write_csv(str(mapped))
    P = parse_axes(MAP)
    columns = dict(w.columns)
    m = np.column_stack([columns[f"m{a}"] for a in "xyz"]) @ P  # raw = Pᵀ (mapped)
    for j, a in enumerate("xyz"):
        columns[f"m{a}"] = m[:, j]
        columns[f"a{a}"] = -columns[f"a{a}"]
    logged = folder / "logged.csv"
    names = list(columns)
    data = np.column_stack([columns[k] for k in names])
    np.savetxt(logged, data, delimiter=",", header=",".join(names), comments="", fmt="%.9g")
    before = fieldcal.calibrate_log(mapped, gyro=False)
    folded = fieldcal.calibrate_log(logged, gyro=False, mag_axes=MAP, accel_sign="gravity")
    return P, w, before, folded


def test_the_folded_terms_are_the_mapped_fits(logs):
    P, _, before, folded = logs
    assert "temperature" in folded.options and folded.options["temperature"]["orders"]
    for sensor, T in (("mag", P), ("accel", -np.eye(3))):
        a, b = folded.sensor(sensor).temperature, before.sensor(sensor).temperature
        assert a.order == b.order >= 1
        # the same problem after the map: equal to the optimiser's tolerance, far inside σ
        np.testing.assert_allclose(a.coefficients, b.coefficients @ T, atol=1e-3 * b.std.max())
        # the error bars follow the map: a signed permutation moves them between axes
        np.testing.assert_allclose(a.std, b.std @ np.abs(T), rtol=1e-3)


def test_the_folded_calibration_corrects_the_readings_as_logged(logs):
    P, _, before, folded = logs
    rng = np.random.default_rng(0)
    T = rng.uniform(18.0, 42.0, 50)
    mapped = rng.normal(size=(50, 3)) + np.asarray(before.mag.bias)
    want = before.correct_mag(mapped, temperature=T)
    got = folded.correct_mag(mapped @ P, temperature=T)  # the magnetometer as logged
    assert np.abs(got - want).max() < 1e-6 * np.abs(want).max()
    accel = rng.normal(size=(50, 3)) + np.asarray(before.accel.bias)
    want = before.correct_accel(accel, temperature=T)
    got = folded.correct_accel(-accel, temperature=T)  # gravity as the board reports it
    assert np.abs(got - want).max() < 1e-6 * np.abs(want).max()
    assert folded.options["mag_axes"] == MAP and folded.options["accel_sign"] == "gravity"
