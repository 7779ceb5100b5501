"""The χ² certificate and the pose table (fieldcal.trust.certificate): the p-value against
scipy.stats' χ² tail, J at the truth distributed as χ² with 6N degrees of freedom over seeds,
and the pose table's columns as known answers."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats as scipy_stats

import fieldcal
from fieldcal.stats.pose_stats import summarize
from fieldcal.trust.certificate import certify, pose_table
from fieldcal.trust.evaluate import evaluate

N = 10


def _evaluation(seed: int):
    s = fieldcal.simulate("paper", seed=seed, n_poses=N)
    stats = summarize(s.accel, s.mag)
    return s, stats, evaluate(s.truth, stats, "accel")


def test_p_value_is_the_chi2_upper_tail():
    _, _, ev = _evaluation(4)
    d = certify(ev, "ok")
    assert d.statistic == pytest.approx(float(ev.pose_cost.sum()), rel=1e-12)
    assert d.dof == ev.dof and d.status == "ok"
    assert d.p_value == pytest.approx(scipy_stats.chi2.sf(d.statistic, d.dof), rel=1e-9)
    np.testing.assert_array_equal(d.pose_cost, ev.pose_cost)


def test_no_degrees_of_freedom_gives_no_p_value():
    # joint fit: 3N − 22 degrees of freedom, none left with 7 poses
    s = fieldcal.simulate("paper", seed=4, n_poses=7)
    ev = evaluate(s.truth, summarize(s.accel, s.mag), "accel")
    assert ev.dof == 3 * 7 - 22
    assert np.isnan(certify(ev, "").p_value)


def test_cost_at_the_truth_is_chi2_with_six_per_pose():
    # at the true parameters every pose adds 6 whitened squares: J ~ χ²(6N) (Σ estimated from
    # the pooled samples: a small excess, well inside the tolerance below)
    costs = [float(_evaluation(seed)[2].pose_cost.sum()) for seed in range(40)]
    mean, k = float(np.mean(costs)), 6 * N
    assert abs(mean - k) < 4 * np.sqrt(2 * k / len(costs))


def test_pose_table_columns():
    s, stats, ev = _evaluation(2)
    index = np.arange(N) * 3 + 1  # the caller's pose numbers
    rows = pose_table(ev, stats, index)
    assert [r["index"] for r in rows] == index.tolist()
    assert sum(r["share"] for r in rows) == pytest.approx(1.0, rel=1e-12)
    for i, r in enumerate(rows):
        assert r["cost"] == pytest.approx(float(ev.pose_cost[i]), rel=1e-12)
        assert r["accel_samples"] == s.counts[i] and r["samples"] == s.counts[i]
        assert r["mag_residual"] == pytest.approx((-ev.raw["mag"][i]).tolist(), rel=1e-12)
        assert "accel_trimmed" not in r and "temperature" not in r


def test_pose_table_of_a_perfect_fit_has_zero_shares():
    _, stats, ev = _evaluation(3)
    perfect = dataclasses.replace(ev, whitened=np.zeros_like(ev.whitened))
    rows = pose_table(perfect, stats, np.arange(N))
    assert all(r["share"] == 0.0 and r["cost"] == 0.0 for r in rows)
    assert certify(perfect, "").p_value == 1.0
