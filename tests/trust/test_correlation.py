"""Error bars widened for correlated neighbouring poses (fieldcal.trust.correlation): τ of an
AR(1) series against its closed form ``(1 + φ)/(1 − φ)``, white noise at 1, invariance to the
residuals' scale, and the covariance multiplied by exactly τ."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from _known import known_calibration

from fieldcal.calibration import Diagnostics, ParameterCovariance
from fieldcal.trust.correlation import (
    FEWEST_POSES,
    STATUS,
    measure_correlation,
    widen_for_correlation,
)


def _ar1(phi: float, n: int, d: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    e = rng.normal(size=(n, d))
    x = np.empty_like(e)
    x[0] = e[0] / np.sqrt(1 - phi**2)
    for k in range(1, n):
        x[k] = phi * x[k - 1] + e[k]
    return x


@pytest.mark.parametrize("phi", [0.5, 0.8])
def test_tau_of_an_ar1_series_is_its_closed_form(phi):
    tau = (1 + phi) / (1 - phi)
    found = measure_correlation(_ar1(phi, 20_000, 3, seed=1))
    # Sokal: var(τ̂) ≈ 2(2M + 1)/N τ²; 4 standard deviations
    sd = tau * np.sqrt(2 * (2 * found.lags + 1) / 20_000)
    assert found.reached and abs(found.tau - tau) < 4 * sd
    assert found.lags >= 5 * found.tau - 1e-9  # Sokal's window rule
    assert found.widening == pytest.approx(np.sqrt(found.tau))
    assert found.effective == pytest.approx(20_000 / found.tau)


def test_white_noise_is_independent_and_scale_does_not_matter():
    x = np.random.default_rng(2).normal(size=(5000, 3))
    found = measure_correlation(x)
    assert abs(found.tau - 1.0) < 4 * np.sqrt(2 * (2 * found.lags + 1) / 5000)
    scaled = measure_correlation(1e6 * x + 7.0)  # centred and normalised by lag 0
    assert scaled.tau == pytest.approx(found.tau, rel=1e-9) and scaled.lags == found.lags
    one_d = measure_correlation(x[:, 0])
    assert one_d.poses == 5000


def test_a_constant_series_has_no_correlation_to_measure():
    found = measure_correlation(np.ones((50, 3)))
    assert (found.tau, found.lags, found.widening) == (1.0, 0, 1.0)


def test_a_random_walk_does_not_reach_the_window():
    walk = np.cumsum(np.random.default_rng(3).normal(size=(400, 1)), axis=0)
    found = measure_correlation(walk)
    assert not found.reached and found.lags == 100 and found.tau > 10


def _with_residuals(n: int, phi: float) -> object:
    x = _ar1(phi, n, 6, seed=4)
    poses = tuple(
        {"index": i, "accel_residual": x[i, :3].tolist(), "mag_residual": x[i, 3:].tolist()}
        for i in range(n)
    )
    cov = ParameterCovariance(("a", "b"), np.array([[4.0, 1.0], [1.0, 9.0]]))
    diag = Diagnostics(1.0, 1, 0.5, np.zeros(n), "")
    return dataclasses.replace(known_calibration(), poses=poses, covariance=cov, diagnostics=diag)


def test_the_covariance_is_multiplied_by_the_larger_tau():
    cal = _with_residuals(2000, 0.6)
    out = widen_for_correlation(cal)
    record = out.options["pose_correlation"]
    taus = {s: record["sensors"][s]["tau"] for s in ("accel", "mag")}
    assert record["tau"] == max(taus.values()) and record["poses"] == 2000
    np.testing.assert_allclose(out.covariance.matrix, cal.covariance.matrix * record["tau"])
    assert out.diagnostics.status == STATUS
    assert abs(record["tau"] - 4.0) < 1.5  # (1 + 0.6)/(1 − 0.6)


def test_too_few_poses_or_no_residuals_change_nothing():
    few = _with_residuals(FEWEST_POSES - 1, 0.6)
    assert widen_for_correlation(few) is few
    bare = known_calibration()
    assert widen_for_correlation(bare) is bare
