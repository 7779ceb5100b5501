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
from fieldcal.calibration import _sensor_block
from fieldcal.methods.mle import model as mle_model
from fieldcal.stats import poses as pose_stats
from fieldcal.stats import trimming
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
    scale = max(float(np.abs(base[n][0]).max()) for n in base)
    step = 1e-6 * scale
    deltas = np.vstack([np.zeros(30), np.eye(30) * step])
    out = {}
    for k, name in enumerate(("accel", "mag")):
        K, b = base[name]
        d = deltas[:, 12 * k : 12 * k + 12]
        noise = deltas[:, 24 + 3 * k : 27 + 3 * k]
        Kp = K + d[:, :9].reshape(-1, 3, 3)
        rhs = raw[name][None] + (noise - b - d[:, 9:])[:, None, :]
        out[name] = np.linalg.solve(Kp[:, None], rhs[..., None])[..., 0]
    both = accuracy._heading(out["accel"], out["mag"])
    J = (np.angle(np.exp(1j * (both[1:] - both[0]))) / step).T
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
    # both are finite differences with a step of 1e-6 of the gains: they agree to rounding
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
    from fieldcal.methods.mle import lm

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
    ref, cal = fieldcal.calibrate(s.accel, s.mag), fieldcal.calibrate(accel, mag)
    np.testing.assert_array_equal(cal.accel.gain, ref.accel.gain * factor)
    np.testing.assert_array_equal(cal.mag.bias, ref.mag.bias * factor)
    assert cal.verdict == ref.verdict and cal.dip_deg == ref.dip_deg


def test_subnormal_readings_are_summarised_without_losing_their_squares():
    """Readings of 1e-310 (below the normal range): squared as they are they would vanish."""
    s = fieldcal.simulate("paper", seed=7)
    tiny = fieldcal.calibrate([a * 1e-310 for a in s.accel], [m * 1e-310 for m in s.mag])
    ref = fieldcal.calibrate(s.accel, s.mag)
    assert tiny.dip_deg == pytest.approx(ref.dip_deg, abs=1e-6)
    assert tiny.verdict.level == ref.verdict.level
