"""The fast paths give what the straightforward computations give.

Every shortcut of the speed work (``docs/benchmarks.md``, section speed) against the plain
computation it replaces: the one-pass, blocked pose statistics against per-pose numpy; the
statistics of scaled readings against those of readings scaled first; the trimming's proof that
nothing can be cut against computing the cut; the heading error's rank-one updates against one
solve per perturbed gain; the shared whitened problem and the single final evaluation against
building and evaluating afresh. Equalities only (exact where the arithmetic is the same), no
timings.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import fieldcal
from fieldcal.covariance import _sensor_block
from fieldcal.likelihood import pose_model as mle_model
from fieldcal.logs import Table, load_log, poses_from_log, stillness
from fieldcal.logs import pose_finding as log_poses
from fieldcal.logs.stillness import detect_still
from fieldcal.simulation.continuous import simulate_continuous
from fieldcal.stats import pose_stats, trimming
from fieldcal.trust import accuracy, fitting


def _reference_stats(poses: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 5 and 7 pose by pose with numpy's own mean and covariance."""
    means = np.array([p[0] + (p - p[0]).mean(axis=0) for p in poses])  # shifted: exact digits
    scatter = sum((len(p) - 1) * np.cov(p.T) for p in poses if len(p) > 1)
    dof = sum(len(p) for p in poses) - len(poses)
    within = np.array([p.var(axis=0).mean() for p in poses])  # trace of the scatter / 3Δ
    return means, scatter / dof, within


@pytest.mark.parametrize(
    "counts",
    [
        [3, 7, 1, 40, 2] * 3,  # many small poses, one block
        [pose_stats.BLOCK + 123, 5, 2 * pose_stats.BLOCK + 7],  # poses split over blocks
        [pose_stats.BLOCK - 3, 10, pose_stats.BLOCK // 2, pose_stats.BLOCK // 2 + 9],  # runs
    ],
)
def test_blocked_summary_matches_per_pose_numpy(counts):
    rng = np.random.default_rng(len(counts))
    # offsets of 1e5 with a noise of 0.1: the per-pose shift must keep Eq. 7's digits
    poses = [1e5 + rng.normal(size=3) * 10 + 0.1 * rng.standard_normal((n, 3)) for n in counts]
    stats = fieldcal.summarize(poses).accel
    means, cov, within = _reference_stats(poses)
    np.testing.assert_allclose(stats.means, means, rtol=1e-14)
    np.testing.assert_allclose(stats.cov, cov, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(stats.scatter, within, rtol=1e-9, atol=1e-12)
    assert stats.dof == sum(counts) - len(counts)


def test_three_dimensional_input_equals_the_list_of_its_poses():
    x = np.random.default_rng(1).normal(size=(9, 50, 3)) + 3.0
    a, b = fieldcal.summarize(x, x), fieldcal.summarize(list(x), list(x))
    assert a == b


@pytest.mark.parametrize("trim", [False, True])
def test_scaled_statistics_equal_those_of_scaled_readings(trim):
    """The statistics are divided by the power of two, not the readings: the same digits."""
    s = fieldcal.simulate("paper", seed=3)
    accel = [p * 16384.0 for p in s.accel]
    mag = [p * 3e-5 for p in s.mag]
    stats, scales, arrays = pose_stats.summarize_scaled(accel, mag, trim=trim)
    for name, poses in (("accel", accel), ("mag", mag)):
        largest = max(float(np.abs(p).max()) for p in poses)
        assert scales[name] == 2.0 ** round(np.log2(largest))  # the nearest power of two
    direct = fieldcal.summarize(
        [p / scales["accel"] for p in accel], [p / scales["mag"] for p in mag], trim=trim
    )
    for name in ("accel", "mag"):
        a, b = stats.sensor(name), direct.sensor(name)
        np.testing.assert_array_equal(a.means, b.means)
        np.testing.assert_array_equal(a.cov, b.cov)
        np.testing.assert_array_equal(a.scatter, b.scatter)
        np.testing.assert_array_equal(a.counts, b.counts)
    assert arrays["accel"][0] is accel[0]  # the readings themselves were not copied


def _median_trim(stacked: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The trimming rule written plainly: numpy medians per pose, the cut mask."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    parts = [stacked[a : a + n] for a, n in zip(starts, counts, strict=True)]
    med = np.array([np.median(p, axis=0) for p in parts])
    mad = np.array([np.median(np.abs(p - m), axis=0) for p, m in zip(parts, med, strict=True)])
    eligible = counts >= trimming.MIN_SAMPLES
    scale = 1.4826 * np.median(mad[eligible], axis=0)
    pose_of = np.repeat(np.arange(len(counts)), counts)
    d2 = np.sum(((stacked - med[pose_of]) / scale) ** 2, axis=1)
    cut = (d2 > trimming.CUT) & eligible[pose_of]
    trimmed = np.bincount(pose_of[cut], minlength=len(counts))
    cut &= ~(trimmed > counts // 2)[pose_of]
    return cut


def _bumped(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    s = fieldcal.simulate("paper", seed=seed, samples=(20, 300))
    poses = [p.copy() for p in s.accel]
    for i in range(0, len(poses), 4):
        k = int(rng.integers(0, len(poses[i]) - 5))
        poses[i][k : k + 5] += rng.normal(0.0, 0.5, (5, 3))
    return np.concatenate(poses), s.counts


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("bumped", [False, True])
def test_trimming_cuts_what_the_plain_rule_cuts(seed, bumped):
    stacked, counts = (
        _bumped(seed)
        if bumped
        else (
            np.concatenate(fieldcal.simulate("paper", seed=seed).accel),
            fieldcal.simulate("paper", seed=seed).counts,
        )
    )
    kept, kept_counts, trimmed = trimming.trim_unsteady(stacked, counts)
    cut = _median_trim(stacked, counts)
    np.testing.assert_array_equal(kept, stacked[~cut])
    np.testing.assert_array_equal(trimmed + kept_counts, counts)
    assert (trimmed.sum() > 0) == bumped


def test_the_proof_that_nothing_is_cut_agrees_with_computing_the_cut(monkeypatch):
    """Skipping the MADs' sort (when their lower bound already rules out any cut) changes
    nothing: the same statistics as with the full computation, bit for bit."""
    proven: list[bool] = []
    original = trimming._none_cut

    def spy(*args: np.ndarray) -> bool:
        proven.append(original(*args))
        return proven[-1]

    for seed in range(8):
        s = fieldcal.simulate("paper", seed=seed)
        monkeypatch.setattr(trimming, "_none_cut", spy)
        fast = fieldcal.summarize(s.accel, s.mag, trim=True)
        monkeypatch.setattr(trimming, "_none_cut", lambda *args: False)
        full = fieldcal.summarize(s.accel, s.mag, trim=True)
        assert fast == full
    assert sum(proven) >= len(proven) // 2  # the shortcut is the usual case on still data


def _heading_by_solves(cal: fieldcal.Calibration) -> float:
    """The heading error with one solve per perturbed gain (what the rank-one updates skip)."""
    raw = {
        n: (accuracy._LEVEL @ cal.reference(n)) @ cal.sensor(n).gain.T + cal.sensor(n).bias
        for n in ("accel", "mag")
    }
    base = {n: (cal.sensor(n).gain, cal.sensor(n).bias) for n in ("accel", "mag")}
    # each sensor's gain, bias and noise step by 1e-6 of its own largest gain entry
    step = np.repeat([1e-6 * float(np.abs(base[n][0]).max()) for n in base], [12, 12])
    step = np.concatenate([step, np.repeat(step[[0, 12]], 3)])
    deltas = np.vstack([np.zeros(30), np.diag(step)])
    out = {}
    for k, name in enumerate(("accel", "mag")):
        K, b = base[name]
        d = deltas[:, 12 * k : 12 * k + 12]
        noise = deltas[:, 24 + 3 * k : 27 + 3 * k]
        Kp = K + d[:, :9].reshape(-1, 3, 3)
        rhs = raw[name][None] + (noise - b - d[:, 9:])[:, None, :]
        out[name] = np.linalg.solve(Kp[:, None], rhs[..., None])[..., 0]
    both = accuracy._heading(out["accel"], out["mag"])
    J = (np.angle(np.exp(1j * (both[1:] - both[0]))) / step[:, None]).T
    C = np.zeros((30, 30))
    names = [n for s in ("accel", "mag") for n in _sensor_block(cal.covariance, s).names]
    full = [f"{s}.{n}" for s, part in (("accel", names[:12]), ("mag", names[12:])) for n in part]
    idx = [cal.covariance.index(n) for n in full]
    C[:24, :24] = cal.covariance.matrix[np.ix_(idx, idx)]
    C[24:27, 24:27] = np.eye(3) * cal.accel.pose_noise_std**2
    C[27:30, 27:30] = np.eye(3) * cal.mag.pose_noise_std**2
    return float(np.degrees(np.sqrt(np.mean(np.einsum("hp,pq,hq->h", J, C, J)))))


@pytest.mark.parametrize(("preset", "seed"), [("paper", 0), ("paper", 5), ("hard", 2)])
def test_heading_error_by_rank_one_updates_equals_perturbed_solves(preset, seed):
    s = fieldcal.simulate(preset, seed=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = fieldcal.calibrate(s.accel, s.mag)
    # both are finite differences with a step of 1e-6 of each sensor's gains: they agree to rounding
    # amplified by that step, far below the prediction's own precision
    assert accuracy._heading_error(cal) == pytest.approx(_heading_by_solves(cal), rel=1e-8)


def test_the_whitened_problem_is_built_once_per_statistics():
    s = fieldcal.simulate("paper", seed=2)
    stats = fieldcal.summarize(s.accel, s.mag)
    problem = mle_model.build_problem(stats, "accel")
    assert mle_model.build_problem(stats, "accel") is problem
    fresh = mle_model._build_problem(stats, "accel")
    for name in ("linv", "means", "start_chol", "start_weight", "start_mu"):
        for sensor in stats.sensors:
            np.testing.assert_array_equal(
                getattr(problem, name)[sensor], getattr(fresh, name)[sensor]
            )
    # a copy with other variances is another problem
    other = stats.replace(accel=stats.accel.with_pose_var(1e-6))
    assert mle_model.build_problem(other, "accel") is not problem


def test_the_final_evaluation_is_reused_only_when_it_is_the_same(monkeypatch):
    """The ML result is evaluated once; forcing a second evaluation gives the same result."""
    s = fieldcal.simulate("paper", seed=4)
    once = fieldcal.calibrate(s.accel, s.mag)
    original = fitting._finish

    def evaluate_again(cal, ml, *args):
        return original(cal.with_raw_scale({}, options={}), ml, *args)  # a copy: not ``ml``

    monkeypatch.setattr(fitting, "_finish", evaluate_again)
    twice = fieldcal.calibrate(s.accel, s.mag)
    assert once == twice


def test_cached_sensor_blocks_equal_fresh_ones():
    s = fieldcal.simulate("paper", seed=6)
    cal = fieldcal.calibrate(s.accel, s.mag)
    cov = cal.covariance
    for name in ("accel", "mag"):
        assert cov.sensor_blocks[name] == _sensor_block(cov, name)
        assert cal.sensor(name).covariance is cov.sensor_blocks[name]
    scaled = cov.scaled({"accel.gain": 2.0})
    assert scaled.sensor_blocks["accel"] == _sensor_block(scaled, "accel")
    assert scaled.index("mag.bias[2]") == list(scaled.names).index("mag.bias[2]")


def test_spread_check_by_eigenvalues_names_the_svd_normal():
    """The plane's normal from the 3x3 scatter's eigenvector is the SVD's."""
    rng = np.random.default_rng(8)
    angles = rng.uniform(0, 2 * np.pi, 12)
    tilt = np.array([[1, 0, 0], [0, np.cos(0.3), -np.sin(0.3)], [0, np.sin(0.3), np.cos(0.3)]])
    means = np.stack([np.cos(angles), np.sin(angles), np.zeros(12)], axis=1) @ tilt.T
    stats = fieldcal.stats_from_means(means + 0.5, means)
    centred = means - means.mean(axis=0)
    normal = np.linalg.svd(centred)[2][2]
    normal *= np.sign(normal[np.argmax(np.abs(normal))])
    shown = f"normal ({normal[0]:+.2f}, {normal[1]:+.2f}, {normal[2]:+.2f})"
    with pytest.raises(ValueError, match="lie in one plane") as info:
        pose_stats.check_spread(stats)
    assert shown in str(info.value)


def test_the_reduced_system_solve_refuses_a_singular_matrix_as_numpy_does():
    from fieldcal.likelihood import levenberg as lm

    S = np.diag([1.0, 2.0, 0.0])
    with pytest.raises(np.linalg.LinAlgError):
        lm._solve(S, np.ones(3))
    A = np.random.default_rng(9).normal(size=(22, 22))
    A = A @ A.T + np.eye(22)
    b = np.arange(22.0)
    np.testing.assert_allclose(lm._solve(A, b), np.linalg.solve(A, b), rtol=1e-12)


@pytest.mark.parametrize("power", [-1000, -20, 37, 460])
def test_powers_of_two_change_no_digit_of_the_statistics_or_the_fit(power):
    """The sums are taken in a unit that is a power of two of the readings' size, so readings
    scaled by 2^k give the same statistics, and the same fit, to the last bit."""
    s = fieldcal.simulate("paper", seed=7)
    factor = 2.0**power
    accel, mag = [a * factor for a in s.accel], [m * factor for m in s.mag]
    for trim in (False, True):
        base, _, _ = pose_stats.summarize_scaled(s.accel, s.mag, trim=trim)
        scaled, _, _ = pose_stats.summarize_scaled(accel, mag, trim=trim)
        assert base == scaled
    ref = fieldcal.calibrate(s.accel, s.mag)
    if factor < 1e-200:
        # a gain this small is no calibration file fieldcal reads back (issue 22: refused on
        # load, naming the key), so the fit refuses it in one line rather than write it
        with pytest.raises(ValueError, match=r"gain's smallest scale .* below 1e-200") as info:
            fieldcal.calibrate(accel, mag)
        assert "\n" not in str(info.value)
        return
    cal = fieldcal.calibrate(accel, mag)
    np.testing.assert_array_equal(cal.accel.gain, ref.accel.gain * factor)
    np.testing.assert_array_equal(cal.mag.bias, ref.mag.bias * factor)
    # the same verdict, but for the warning that no unit explains such a scale (issue 35, S3)
    kept = tuple(r for r in cal.verdict.reasons if r.code != "unexplained_scale")
    assert kept == ref.verdict.reasons and cal.dip_deg == ref.dip_deg
    assert len(kept) < len(cal.verdict.reasons)  # 2^-20, 2^37, 2^460: no unit is that


def test_subnormal_readings_are_summarised_without_losing_their_squares():
    """Readings of 1e-310 (below the normal range): squared as they are they would vanish; the
    statistics are those of the readings at their normal size, scaled."""
    s = fieldcal.simulate("paper", seed=7)
    factor = 2.0**-1030  # subnormal: the readings keep 44 of their 52 bits
    tiny, _, _ = pose_stats.summarize_scaled(
        [a * factor for a in s.accel], [m * factor for m in s.mag], trim=False
    )
    base, _, _ = pose_stats.summarize_scaled(s.accel, s.mag, trim=False)
    for got, want in ((tiny.accel, base.accel), (tiny.mag, base.mag)):
        np.testing.assert_allclose(got.means, want.means, rtol=1e-11, atol=1e-14)
        np.testing.assert_allclose(got.cov, want.cov, rtol=1e-9, atol=1e-16)  # squares kept


# ------------------------------------------------------------------ still detection, trimming
# The shortcuts of the still detection and the per-pose trimming on logs of 10^6 samples,
# each against the computation it replaces (written here as it was), to the last bit.


def _key_sort_statistics(x: np.ndarray, counts: np.ndarray, ranks: np.ndarray) -> np.ndarray:
    """Order statistics as the trimming first took them: one sort of the keys
    ``pose · span + (x − low)`` of all the poses, read back as ``key − pose · span + low``."""
    index = np.repeat(np.arange(len(counts)), counts)
    starts = np.cumsum(counts) - counts
    low = x.min(axis=1, keepdims=True)
    span = 2.0 * (x.max(axis=1, keepdims=True) - low)
    span[span == 0] = 1.0
    keys = index * span + (x - low)
    keys.sort(axis=1)
    out = np.full((ranks.shape[1], x.shape[0], len(counts)), np.nan)
    for j in range(ranks.shape[1]):
        for i in np.flatnonzero(ranks[:, j] >= 0):
            k = starts[i] + ranks[i, j]
            out[j, :, i] = keys[:, k] - index[k] * span[:, 0] + low[:, 0]
    return out


def _poses_around_the_selection_size(seed: int, quantum: float = 0.0) -> list[np.ndarray]:
    """Poses on both sides of trimming.SELECT (partitions above, one sort below), odd and
    even counts, tiny poses, bumps; ``quantum``: readings rounded to it (ties)."""
    rng = np.random.default_rng(seed)
    counts = [5, 9, 10, 11, trimming.SELECT - 1, trimming.SELECT, trimming.SELECT + 1, 5000]
    counts += [100, 3, 4096, 1, 2, 777, 12]
    poses = []
    for n in counts:
        p = rng.normal(size=3) * 9.8 + 0.01 * rng.standard_normal((n, 3))
        if n > 40 and rng.random() < 0.6:  # a bump
            k = int(rng.integers(0, n - 30))
            p[k : k + 30] += rng.normal(0.0, 0.2, (30, 3))
        poses.append(np.round(p / quantum) * quantum if quantum else p)
    return poses


@pytest.mark.parametrize(("seed", "quantum"), [(0, 0.0), (1, 0.0), (2, 0.004), (3, 0.05)])
def test_order_statistics_by_partitions_equal_those_of_the_key_sort(seed, quantum):
    """Large poses select their order statistics by partitions and apply the key's arithmetic
    to the selected readings only; small ones share a sort: both give the sorted keys' values."""
    poses = _poses_around_the_selection_size(seed, quantum)
    counts = np.array([len(p) for p in poses])
    x = np.ascontiguousarray(np.concatenate(poses).T)
    lo = (counts - 1) // 2
    ranks = np.column_stack([lo // 2, lo, counts // 2, lo // 2 + lo + 1])
    ranks[counts < trimming.MIN_SAMPLES, 0] = ranks[counts < trimming.MIN_SAMPLES, 3] = -1
    expected = _key_sort_statistics(x, counts, ranks)
    found = trimming.unsteady(x.copy(), counts, np.empty((4, x.shape[1])))
    np.testing.assert_array_equal(found.medians, 0.5 * (expected[1] + expected[2]))
    # the MADs: the same statistics of the absolute deviations from those medians, read by
    # partitions (large poses) or from each pose's sorted readings (window search), bit for bit
    starts = np.cumsum(counts) - counts
    runs = list(trimming._small(starts, counts))
    ordered = np.concatenate(
        [
            np.sort(x[:, s : s + n], axis=1)
            for s, n in zip(starts, counts, strict=True)
            if n < trimming.SELECT
        ],
        axis=1,
    )
    deviations = x - np.repeat(found.medians, counts, axis=1)
    mads = trimming._mads(deviations, starts, counts, ranks[:, 1:3], ordered, runs, found.medians)
    plain = np.stack(
        [
            np.median(np.abs(deviations[:, s : s + n]), axis=1)
            for s, n in zip(starts, counts, strict=True)
        ],
        axis=1,
    )
    np.testing.assert_array_equal(mads, plain)


@pytest.mark.parametrize("seed", range(3))
def test_trimming_of_large_poses_cuts_what_the_plain_rule_cuts(seed):
    poses = _poses_around_the_selection_size(seed + 10)
    stacked, counts = np.concatenate(poses), np.array([len(p) for p in poses])
    kept, kept_counts, trimmed = trimming.trim_unsteady(stacked, counts)
    cut = _median_trim(stacked, counts)
    assert cut.any()
    np.testing.assert_array_equal(kept, stacked[~cut])
    np.testing.assert_array_equal(trimmed + kept_counts, counts)


def test_trimming_leaves_an_f_ordered_input_as_it_was():
    stacked = np.asfortranarray(np.concatenate(_poses_around_the_selection_size(4)))
    before = stacked.copy()
    trimming.trim_unsteady(stacked, np.array([len(p) for p in _poses_around_the_selection_size(4)]))
    np.testing.assert_array_equal(stacked, before)


def test_candidates_by_weighted_squares_give_the_cut_of_every_sample():
    """d² is computed exactly only where the weighted squares (one product) do not rule a cut
    out: the same samples as d² = einsum((x − m) / s) for all of them."""
    rng = np.random.default_rng(5)
    deviations = rng.standard_normal((3, 300_000)) * [[1.0], [2.0], [0.5]]
    deviations[:, rng.choice(300_000, 40, replace=False)] *= 4.0  # beyond the cut
    scale = np.array([1.0, 2.0, 0.5]) * 1.02
    for usable in (np.array([True, True, True]), np.array([True, False, True])):
        # and samples a hair's breadth on either side of it
        near = rng.choice(300_000, 40, replace=False)
        z = deviations[:, near][usable] / scale[usable, None]
        ratio = trimming.CUT / (np.sum(z * z, axis=0) * (3.0 / usable.sum()))
        ratio *= 1.0 + np.tile([-1e-4, -1e-7, 1e-10, 1e-7, 1e-4], 8)
        deviations[:, near] *= np.sqrt(ratio)
        z = deviations[usable] / scale[usable, None]
        d2 = np.einsum("ij,ij->j", z, z) * (3.0 / usable.sum())
        found = trimming._beyond(
            deviations, deviations**2, np.where(usable, scale, 0.0), usable, np.empty(300_000)
        )
        np.testing.assert_array_equal(found, np.flatnonzero(d2 > trimming.CUT))
        assert 20 < found.size < 150


@pytest.mark.parametrize("cuts", [0, 1, 7, 3000])
def test_kept_columns_by_slices_equal_compress(cuts):
    rng = np.random.default_rng(cuts)
    x = rng.standard_normal((3, 50_000))
    cut = np.zeros(50_000, dtype=bool)
    cut[rng.choice(50_000, cuts, replace=False)] = True
    cut[[0, -1]] = cuts > 0  # at the ends too
    out = np.empty((3, int((~cut).sum())))
    np.testing.assert_array_equal(pose_stats._kept(x, cut, out), np.compress(~cut, x, axis=1))


def test_numpy_orders_of_summation_the_shortcuts_rely_on():
    """Running sums give numpy's sum over the rows of an (n, 3) array; the three axes of a row
    summed left to right are its .sum(axis=1); (z₀² + z₁²) + z₂² is einsum's d²."""
    rng = np.random.default_rng(6)
    for n in (1, 2, 7, 1000, 65_537):
        x = rng.standard_normal((n, 3)) * [1.0, 1e-3, 5.0] + [0.3, -9.8, 0.1]
        np.testing.assert_array_equal(stillness._column_sums(x), x.sum(axis=0))
        mean, var = stillness._mean_var(x)
        np.testing.assert_array_equal(mean, x.mean(axis=0))
        np.testing.assert_array_equal(var, x.var(axis=0))
        np.testing.assert_array_equal(x[:, 0] + x[:, 1] + x[:, 2], x.sum(axis=1))
        z = np.ascontiguousarray(x.T)
        np.testing.assert_array_equal(
            (z[0] * z[0] + z[1] * z[1]) + z[2] * z[2], np.einsum("ij,ij->j", z, z)
        )


@pytest.mark.parametrize("n", [1, 2, 3, 10, 11, 1000, 100_001])
def test_quantile_and_median_by_one_partition_equal_numpy(n):
    rng = np.random.default_rng(n)
    x = rng.standard_normal((n, 3)) ** 2
    x[rng.random(n) < 0.2] = 0.0  # ties
    for q in (0.0, 0.1, 0.25, 0.5, 0.9, 1.0, 1 / 3):
        assert stillness._quantile(x[:, 0].copy(), q) == float(np.quantile(x[:, 0], q))
    rows = rng.random(n) < 0.7
    np.testing.assert_array_equal(stillness._median_columns(x, None), np.median(x, axis=0))
    if rows.any():
        np.testing.assert_array_equal(
            stillness._median_columns(x, rows), np.median(x[rows], axis=0)
        )


def _moving_variance_as_it_was(x: np.ndarray, window: int) -> np.ndarray:
    """The moving variance with a temporary per step (no shared sums, no division in place)."""
    x = x - x.mean(axis=0)
    n, half = len(x), window // 2
    c1 = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)])
    c2 = np.vstack([np.zeros((1, 3)), np.cumsum(x * x, axis=0)])
    lo, hi = np.clip(np.arange(n) - half, 0, n), np.clip(np.arange(n) + half + 1, 0, n)
    count = (hi - lo).astype(float)[:, None]
    mean = (c1[hi] - c1[lo]) / count
    var = np.maximum((c2[hi] - c2[lo]) / count - mean**2, 0.0)
    return var.sum(axis=1)


@pytest.mark.parametrize("window", [3, 25, 101])
def test_moving_variance_from_shared_sums_equals_the_plain_one(window):
    rng = np.random.default_rng(window)
    x = rng.standard_normal((20_000, 3)) * 1e-3 + [0.1, -9.8, 0.2]
    x[5000:6000] += np.linspace(0, 3, 1000)[:, None]
    np.testing.assert_array_equal(
        stillness.moving_variance(x, window), _moving_variance_as_it_was(x, window)
    )


@pytest.mark.parametrize("step", [0.0, 1e-4, 0.02, 0.05, 0.5])
def test_the_floor_from_the_first_rows_equals_the_floor_from_all(step):
    """The resolution term of the noise floor is skipped when the smallest step of the first
    rows already cannot win the max: the same floor as scanning every row."""
    rng = np.random.default_rng(7)
    x = rng.standard_normal((30_000, 3)) * 0.01 + 1.0
    if step:
        x = np.round(x / step) * step
    stat = stillness.moving_variance(x, 25)
    full = max(float(np.quantile(stat, 0.1)), 3.0 * stillness._resolution(x) ** 2 / 12.0, 1e-300)
    head = x[: stillness._HEAD + 1]
    assert stillness._floor(stat, 0.1, head, lambda: x) == full


def _log_of(sim):
    """A simulated continuous log as load_log reads it (no file)."""
    return load_log(Table("simulated.csv", list(sim.columns), dict(sim.columns)))


def test_segment_statistics_serve_as_the_pose_spread_and_means():
    """poses_from_log takes each pose's spread from its still segment (computed as _std
    computes it) and the means from running sums: the numbers of the plain computations."""
    sim = simulate_continuous("paper", seed=4, samples=(3000, 5000))
    log = _log_of(sim)
    found = poses_from_log(log)
    assert found.detection is not None
    for entry, segment, accel, mag in zip(
        found.entries, found.detection.segments, found.accel, found.mag, strict=True
    ):
        assert entry["std"] == log_poses._std(accel)
        np.testing.assert_array_equal(np.array(segment.mean), accel.mean(axis=0))
        assert len(mag) == entry["samples"]
    np.testing.assert_array_equal(found.means("accel"), [p.mean(axis=0) for p in found.accel])
    np.testing.assert_array_equal(found.means("mag"), [p.mean(axis=0) for p in found.mag])


def test_drift_of_the_rests_from_sums_equals_the_two_pass_one():
    """The "still intervals move" check takes each rest's spread from its segment and the
    halves' means from one pass of sums: the two-pass figure within rounding."""
    sim = simulate_continuous("paper", seed=8, samples=(2000, 3000), move_seconds=(3.0, 5.0))
    log = _log_of(sim)
    segments = detect_still(log.accel, log.gyro, window=25, min_samples=50).segments
    spans = np.array([(s.start, s.stop) for s in segments if not s.pieces])
    starts, stops = spans[:, 0], spans[:, 1]
    mids = (starts + stops) // 2
    y = log.accel / stillness.scale_of(log.accel)
    halves = np.column_stack([starts, mids, mids, stops]).reshape(-1, 2)
    hmean = np.array([y[a:b].mean(axis=0) for a, b in halves])
    var = np.array([y[a:b].var(axis=0).sum() for a, b in spans])
    n1, n2 = mids - starts, stops - mids
    jump2 = np.sum((hmean[1::2] - hmean[0::2]) ** 2, axis=1)
    drift = np.sqrt(np.maximum(jump2 - var * (1.0 / n1 + 1.0 / n2), 0.0))
    means = np.array([y[a:b].mean(axis=0) for a, b in spans])
    expected = float(np.median(drift)) / float(np.median(np.linalg.norm(means, axis=1)))
    assert log_poses._still_drift(log.accel, "accel", segments) == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("quantum", [0.0, 0.25])
def test_window_search_gives_every_rank_of_the_absolute_deviations(quantum):
    """_window_order's search (on positions in the flat array, overshooting where no window
    crosses) gives, for any rank, the sorted absolute deviations' value, bit for bit."""
    rng = np.random.default_rng(13)
    counts = np.array([1, 2, 3, 4, 7, 10, 31, 64, 100, 513])
    x = rng.normal(size=(3, counts.sum())) * 3.0
    if quantum:
        x = np.round(x / quantum) * quantum  # ties
    starts = np.cumsum(counts) - counts
    poses = list(zip(starts.tolist(), counts.tolist(), strict=True))
    y = np.concatenate([np.sort(x[:, s : s + n], axis=1) for s, n in poses], axis=1)
    m = np.stack([np.median(y[:, s : s + n], axis=1) for s, n in poses], axis=1)
    for fraction in (0.0, 0.3, 0.5, 0.8, 1.0):  # ranks from the nearest to the farthest
        ranks = np.round(fraction * (counts - 1)).astype(np.int64)
        got = trimming._window_order(y, counts, np.column_stack([ranks, counts // 2]), m)
        for i, (s, n) in enumerate(poses):
            plain = np.sort(np.abs(y[:, s : s + n] - m[:, i : i + 1]), axis=1)
            np.testing.assert_array_equal(got[0, :, i], plain[:, ranks[i]])
            np.testing.assert_array_equal(got[1, :, i], plain[:, n // 2])
