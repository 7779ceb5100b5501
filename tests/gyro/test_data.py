"""What the gyroscope's fit takes from a log, computed for all poses and segments at once,
against the pose-by-pose and segment-by-segment computation."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.gyro.data import build_segments, check_rows, pose_statistics
from fieldcal.simulation.continuous import simulate_continuous


@pytest.fixture(scope="module")
def log():
    sim = simulate_continuous("paper", seed=5, n_poses=9)
    c = sim.columns
    return (
        c["t"],
        np.column_stack([c["gx"], c["gy"], c["gz"]]),
        check_rows(sim.segments, len(c["t"])),
    )


@pytest.mark.parametrize("hold", ["midpoint", "previous"])
def test_segments_are_the_segment_by_segment_intervals(log, hold):
    t, g, rows = log
    times = pose_statistics(t, g, rows)[1]
    links = np.array([0, 1, 2, 4, 5, 7])  # with gaps
    data = build_segments(t, g, rows, links, times, hold)
    for m, k in enumerate(links):
        a, c = rows[k, 1] - 1, rows[k + 1, 0]
        x, tt = g[a : c + 1], t[a : c + 1]
        u = 0.5 * (x[1:] + x[:-1]) if hold == "midpoint" else x[:-1]
        mid = 0.5 * (tt[1:] + tt[:-1]) if hold == "midpoint" else tt[:-1]
        part = slice(data.first[m], data.last[m] + 1)
        np.testing.assert_array_equal(data.raw[part], u)
        np.testing.assert_array_equal(data.dt[part], np.diff(tt))
        lam = (mid - times[k]) / (times[k + 1] - times[k])
        np.testing.assert_allclose(data.lam[part], lam, rtol=0, atol=1e-15)
        assert np.all(data.seg[part] == m) and data.rows[m] == (a, c)
    assert data.last[-1] + 1 == len(data.dt)


def test_pose_statistics_are_the_pose_by_pose_ones(log):
    t, g, rows = log
    means, times, durations, cov, dof, Q = pose_statistics(t, g, rows)
    steps = np.diff(t)
    typical = float(np.median(steps[steps > 0]))
    scatter = np.zeros((3, 3))
    for i, (a, b) in enumerate(rows):
        np.testing.assert_allclose(means[i], g[a:b].mean(axis=0), rtol=1e-13)
        np.testing.assert_allclose(times[i], t[a:b].mean(), rtol=1e-13)
        assert durations[i] == pytest.approx(t[b - 1] - t[a] + typical, rel=1e-13)
        d = g[a:b] - g[a:b].mean(axis=0)
        scatter += d.T @ d
    assert dof == int(np.sum(rows[:, 1] - rows[:, 0] - 1))
    np.testing.assert_allclose(cov, scatter / dof, rtol=1e-12)
    # white noise here: the block means agree with it, Q is the white-noise density
    np.testing.assert_allclose(Q, cov * typical, rtol=1e-12)


def test_a_wandering_bias_raises_the_noise_density(log):
    t, g, rows = log
    walk = np.cumsum(np.random.default_rng(0).normal(scale=0.002, size=g.shape), axis=0)
    Q_white = pose_statistics(t, g, rows)[5]
    Q_wander = pose_statistics(t, g + walk, rows)[5]
    cov = pose_statistics(t, g + walk, rows)[3]
    typical = float(np.median(np.diff(t)))
    assert np.trace(Q_wander) > 1.5 * np.trace(cov * typical)  # the block check's factor
    assert np.trace(Q_wander) > np.trace(Q_white)
