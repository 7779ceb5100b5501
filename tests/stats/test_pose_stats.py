"""Pose statistics (Eq. 5, 7) against a hand computation, and the input checks."""

import numpy as np
import pytest

import fieldcal
from fieldcal.stats.pose_stats import check_spread, stats_from_means


def test_summarize_matches_a_hand_computation():
    a = [np.array([[1.0, 2, 3], [3, 2, 1]]), np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 5]])]
    stats = fieldcal.summarize(a, a)
    np.testing.assert_allclose(stats.accel.means, [[2, 2, 2], [1, 1, 2]])  # Eq. 5
    np.testing.assert_array_equal(stats.accel.counts, [2, 3])
    # Eq. 7 by hand: deviations (-1,0,1),(1,0,-1) | (-1,-1,-2),(0,0,-1),(1,1,3); ΣΔ − N = 3
    devs = np.array([[-1, 0, 1], [1, 0, -1], [-1, -1, -2], [0, 0, -1], [1, 1, 3]], float)
    np.testing.assert_allclose(stats.accel.cov, devs.T @ devs / 3)
    assert stats.accel.dof == 3
    assert stats.mag == stats.accel


def test_summarize_agrees_with_numpy_per_pose_statistics():
    rng = np.random.default_rng(5)
    poses = [rng.normal(size=(n, 3)) * [1, 2, 3] + 10 for n in rng.integers(2, 60, 40)]
    stats = fieldcal.summarize(poses)
    np.testing.assert_allclose(stats.accel.means, [p.mean(axis=0) for p in poses])
    scatter = sum((len(p) - 1) * np.cov(p.T) for p in poses)
    np.testing.assert_allclose(stats.accel.cov, scatter / (sum(map(len, poses)) - len(poses)))
    assert stats.mag is None and stats.n_poses == 40


def test_pooled_covariance_is_unbiased():
    """Eq. 7 divides by ΣΔ − N: its mean over many sessions equals the true Σ."""
    rng = np.random.default_rng(6)
    cov = np.array([[2.0, 0.3, 0], [0.3, 1.0, -0.2], [0, -0.2, 0.5]])
    L = np.linalg.cholesky(cov)
    estimates = [
        fieldcal.summarize([rng.standard_normal((3, 3)) @ L.T + k for k in range(4)]).accel.cov
        for _ in range(4000)
    ]
    # each estimate has ν = 8 degrees of freedom; the mean over 4000 has sd ≈ sqrt(2/8/4000) Σ
    np.testing.assert_allclose(np.mean(estimates, axis=0), cov, atol=0.05)


def test_single_sample_poses_have_no_covariance():
    stats = fieldcal.summarize([np.ones((1, 3)) * k for k in range(9)])
    assert stats.accel.cov is None and stats.accel.dof == 0
    stats = stats_from_means(np.arange(27.0).reshape(9, 3), np.ones((9, 3)))
    assert stats.accel.cov is None and np.all(stats.mag.counts == 1)


def test_three_dimensional_array_input():
    x = np.random.default_rng(0).normal(size=(8, 20, 3))
    np.testing.assert_allclose(fieldcal.summarize(x).accel.means, x.mean(axis=1))


@pytest.mark.parametrize(
    ("accel", "mag", "message"),
    [
        ([np.ones((5, 3))] * 9, [np.ones((5, 3))] * 8, "accel has 9 poses but mag has 8"),
        ([np.ones((5, 2))] * 9, None, r"pose 0 has shape \(5, 2\)"),
        ([np.ones((5, 3))] * 8 + [np.full((5, 3), np.nan)], None, "NaN or inf readings in 1"),
        ([np.ones((5, 3))] * 8 + [np.full((5, 3), np.inf)], None, r"pose\(s\) \(8\)"),
        (np.ones((50, 3)), None, "one .* array per static pose"),
        ([np.ones((0, 3))], None, "pose 0 has no samples"),
        ([], None, "no poses given"),
        (None, None, "no data"),
        ([[["a", "b", "c"]]], None, "not numeric"),
    ],
)
def test_bad_input_is_a_one_line_value_error(accel, mag, message):
    with pytest.raises(ValueError, match=message) as info:
        fieldcal.summarize(accel, mag)
    assert "\n" not in str(info.value)


def test_covariance_keeps_its_precision_under_large_offsets():
    """24-bit counts: offsets of 4e6 and a noise of 2 counts must not cancel away Eq. 7."""
    rng = np.random.default_rng(9)
    centre = np.array([4.0e6, -3.5e6, 4.2e6])
    directions = rng.normal(size=(20, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    poses = [centre + 1e4 * d + 2.0 * rng.standard_normal((300, 3)) for d in directions]
    stats = fieldcal.summarize(poses)
    scatter = sum((len(p) - 1) * np.cov((p - p[0]).T) for p in poses)
    # 1e-6 counts² is 1e-7 of the variance: ~10⁴ below Eq. 7's own sampling error; without the
    # shift, XᵀX − ΣΔμμᵀ would cancel ~1e13 against 1e13 and keep no digit of the 4 counts²
    np.testing.assert_allclose(stats.accel.cov, scatter / (20 * 300 - 20), rtol=0, atol=1e-6)
    np.testing.assert_allclose(stats.accel.means, [p.mean(axis=0) for p in poses], rtol=1e-14)


def test_single_reading_poses_are_not_trimmed_and_summarised_as_given():
    """No pose of one reading can be trimmed: the trimmed summary is the plain one (no order
    statistics are taken), with zero cuts counted."""
    rng = np.random.default_rng(11)
    a = [rng.normal(size=(1, 3)) * 9.8 for _ in range(24)]
    m = [rng.normal(size=(1, 3)) * 0.4 for _ in range(24)]
    trimmed, plain = fieldcal.summarize(a, m, trim=True), fieldcal.summarize(a, m)
    for name in ("accel", "mag"):
        got, want = trimmed.sensor(name), plain.sensor(name)
        np.testing.assert_array_equal(got.means, want.means)
        np.testing.assert_array_equal(got.means, np.concatenate(a if name == "accel" else m))
        assert got.cov is None and got.dof == 0
        np.testing.assert_array_equal(got.trimmed, np.zeros(24, dtype=np.int64))
        assert want.trimmed is None


@pytest.mark.parametrize("sensor", ["accel", "mag"])
def test_spread_check_names_the_sensor_whose_poses_lie_on_a_line(sensor):
    rng = np.random.default_rng(12)
    spread = rng.normal(size=(12, 3)) + 5.0
    line = np.outer(np.linspace(-1, 1, 12), [0.3, 0.4, 0.5]) + 2.0
    means = {"accel": spread, "mag": spread, sensor: line}
    stats = stats_from_means(means["accel"], means["mag"])
    with pytest.raises(
        ValueError, match=f"the {sensor} readings barely change .* or lie on a line"
    ):
        check_spread(stats)
    check_spread(stats_from_means(spread, spread))  # spread poses pass
