"""The overlapping Allan deviation (fieldcal.stats.allan): a direct O(n·k) computation of the
definition, white noise at σ/√m within its band, χ² quantiles against scipy, records never
differenced across, and the cluster sizes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as scipy_stats

from fieldcal.stats.allan import allan_deviation, chi2_quantile, cluster_sizes, equivalent_dof


def _overlapping_avar(y: np.ndarray, m: int) -> float:
    """The definition: 1/2 the mean square difference of consecutive overlapping m-averages."""
    c = np.convolve(y, np.ones(m) / m, mode="valid")  # every m-sample average
    d = c[m:] - c[:-m]
    return 0.5 * float(np.mean(d * d))


def test_avar_is_the_definition_computed_directly():
    y = np.random.default_rng(1).normal(size=(3000, 2))
    curve = allan_deviation(y, rate=100.0)
    for k, m in enumerate(curve.m):
        for axis in range(2):
            assert curve.avar[k, axis] == pytest.approx(
                _overlapping_avar(y[:, axis], int(m)), rel=1e-9
            )
    np.testing.assert_allclose(curve.taus, curve.m / 100.0)
    np.testing.assert_array_equal(curve.counts, 3000 - 2 * curve.m + 1)


def test_white_noise_lies_within_its_band_around_sigma_over_root_m():
    sigma = 0.3
    y = sigma * np.random.default_rng(2).normal(size=(20_000, 3))
    curve = allan_deviation(y, rate=200.0, confidence=0.999)
    truth = sigma / np.sqrt(curve.m)[:, None]
    inside = (curve.lower <= truth) & (truth <= curve.upper)
    assert inside.mean() > 0.97  # 99.9 % bands; neighbouring τ are correlated
    assert np.all(curve.lower <= curve.adev) and np.all(curve.adev <= curve.upper)


def test_records_are_never_differenced_across():
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(500, 1)), 100.0 + rng.normal(size=(700, 1))  # a jump between them
    joined = allan_deviation([a, b], rate=10.0)
    assert joined.lengths == (500, 700)
    for k, m in enumerate(joined.m):
        m = int(m)
        ma, mb = max(500 - 2 * m + 1, 0), max(700 - 2 * m + 1, 0)
        expected = (ma * _overlapping_avar(a[:, 0], m) if ma else 0.0) + (
            mb * _overlapping_avar(b[:, 0], m) if mb else 0.0
        )
        assert joined.avar[k, 0] == pytest.approx(expected / (ma + mb), rel=1e-9)
    split = np.vstack([a, [[np.nan]], b])  # a NaN row splits a record the same way
    np.testing.assert_allclose(allan_deviation(split, rate=10.0).avar, joined.avar, rtol=1e-12)


@pytest.mark.parametrize("p", [0.0005, 0.16, 0.5, 0.84, 0.9995])
def test_chi2_quantiles_against_scipy(p):
    exact = np.array([1.0, 2.5, 7.0, 30.0])  # an edf is at least 1
    np.testing.assert_allclose(chi2_quantile(p, exact), scipy_stats.chi2.ppf(p, exact), rtol=1e-6)
    if 0.02 <= p <= 0.98:  # the Wilson-Hilferty range stated
        large = np.array([31.0, 200.0, 5000.0])
        np.testing.assert_allclose(
            chi2_quantile(p, large), scipy_stats.chi2.ppf(p, large), rtol=1e-3
        )


def test_white_edf_is_nist_sp1065s_formula_and_at_least_one():
    n, m = 1000, np.array([1, 10, 100, 499])
    N = n + 1
    expected = (3 * (N - 1) / (2 * m) - 2 * (N - 2) / N) * 4 * m**2 / (4 * m**2 + 5)
    np.testing.assert_allclose(equivalent_dof([n], m), np.maximum(expected, 1.0), rtol=1e-12)


def test_cluster_sizes_are_log_spaced_and_unique():
    m = cluster_sizes(10_000, per_decade=10)
    assert m[0] == 1 and m[-1] == 5000 and np.all(np.diff(m) > 0)
    ratios = m[1:] / m[:-1]
    assert ratios[m[1:] > 20].max() < 10 ** (1 / 10) * 1.1
    np.testing.assert_array_equal(cluster_sizes(3), [1])
