"""Still-pose detection: synthetic logs with known boundaries, and real logs.

imucal's hand-made segment list is the score: every annotated static part must be covered to at
least 90 % by one detected interval, and every detected interval must be one of the annotated
orientations (a part of the session may revisit a pose, e.g. before and after the Ferraris
rotations; a revisit is the same pose, not an extra one).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from fieldcal.errors import InputError
from fieldcal.logs import load_log, poses_from_log
from fieldcal.logs.stillness import detect_still, moving_variance
from fieldcal.simulation.continuous import simulate_continuous
from fieldcal.simulation.warmup import simulate_warmup_log


def _accel_gyro(log):
    c = log.columns
    return (
        np.column_stack([c["ax"], c["ay"], c["az"]]),
        np.column_stack([c["gx"], c["gy"], c["gz"]]),
    )


def test_moving_variance_matches_direct():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(200, 3)) * [1, 2, 3] + 1e6  # a large offset must not hurt precision
    got = moving_variance(x, 11)
    i = 100
    assert got[i] == pytest.approx(x[i - 5 : i + 6].var(axis=0).sum(), rel=1e-9)
    assert got[0] == pytest.approx(x[:6].var(axis=0).sum(), rel=1e-9)  # truncated at the ends


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_synthetic_boundaries_found(seed):
    # quiet sensor (noise well under the motion), as a good MEMS part on a bench
    log = simulate_continuous("paper", seed=seed, noise_alpha=(1e-6, 1e-5), n_poses=10)
    accel, gyro = _accel_gyro(log)
    for g in (gyro, None):  # with and without the gyroscope
        result = detect_still(accel, g, window=51, min_samples=100)
        assert len(result.segments) == len(log.segments)
        for seg, (start, stop) in zip(result.segments, log.segments, strict=True):
            # inside the true still interval, and covering at least 80 % of it
            assert start <= seg.start and seg.stop <= stop
            assert seg.samples >= 0.8 * (stop - start)


def test_paper_noise_needs_the_gyro():
    # Table 1's noise (σ up to 0.1 |g|) hides slow turns from the accelerometer; the gyro sees them
    log = simulate_continuous("paper", seed=3, pose_distribution="handheld")
    accel, gyro = _accel_gyro(log)
    assert len(detect_still(accel, gyro, window=51, min_samples=100).segments) == 15


def test_short_gap_of_one_pose_is_merged():
    rng = np.random.default_rng(5)
    accel = rng.normal(scale=0.01, size=(1000, 3)) + np.array([0.0, 0.0, 1.0])
    accel[480:490] += rng.normal(scale=0.3, size=(10, 3))  # a tap on the table
    result = detect_still(accel, window=25, min_samples=50, max_gap=60)
    assert len(result.segments) == 1


def test_too_short_log():
    with pytest.raises(InputError, match="fewer than one detection window"):
        detect_still(np.zeros((5, 3)), window=25)


def test_imucal_annotated_segments(shared_data):
    folder = shared_data("imucal")
    log = load_log(folder / "example_ferraris_session.csv")
    parts = json.loads((folder / "example_ferraris_session_list.json").read_text())
    static = {k: v for k, v in parts.items() if not k.endswith("_rot")}
    # the README's sampling rate (the file has only a sample index): 0.5 s windows, 1 s minimum
    poses = poses_from_log(log, rate=102.4).entries
    matched = {}
    for name, part in static.items():
        a, b = part["start"], part["end"]
        overlap = [max(0, min(p["stop"], b) - max(p["start"], a)) / (b - a) for p in poses]
        best = int(np.argmax(overlap))
        assert overlap[best] >= 0.9, (name, overlap[best])
        matched[name] = poses[best]["orientation"]
    # no extra poses: six distinct orientations, one per annotated part; the other intervals
    # are revisits of those (still before and after each Ferraris rotation)
    assert len(set(matched.values())) == 6
    assert {p["orientation"] for p in poses} == set(matched.values())
    # and no interval inside a rotation (the gyro sees the turn)
    for name in ("x_rot", "y_rot", "z_rot"):
        a, b = parts[name]["start"], parts[name]["end"]
        assert all(min(p["stop"], b) - max(p["start"], a) <= 0.1 * (b - a) for p in poses), name


def test_imu_tk_pose_count(shared_data):
    folder = shared_data("imu_tk")
    acc = np.loadtxt(folder / "xsens_acc.mat")
    gyro = np.loadtxt(folder / "xsens_gyro.mat")
    result = detect_still(acc[:, 1:], gyro[:, 1:], window=51, min_samples=100)  # 100 Hz
    # the Tedaldi protocol: the initial ~50 s rest, then tens of poses held 1-4 s
    assert 30 <= len(result.segments) <= 45
    first = result.segments[0]
    assert first.start < 100 and first.stop / 100 > 45  # the initial rest, about 50 s


@pytest.mark.parametrize(("session", "low", "high"), [("session1", 5, 8), ("session3", 9, 14)])
def test_icm20948_pose_count(shared_data, session, low, high):
    folder = shared_data("icm20948-deadtomgc")
    log = load_log(folder / "derived" / f"{session}.csv")
    rate = 27.0  # no timestamps: the loop sleeps 30 ms per sample
    result = detect_still(log.accel, log.gyro, window=15, min_samples=int(0.5 * rate))
    assert low <= len(result.segments) <= high


@pytest.mark.parametrize(("n", "window"), [(200, 11), (30, 51), (7, 3), (52, 51), (51, 51)])
def test_moving_variance_every_row_against_direct(n, window):
    """Every row, including those whose window the log's ends truncate (the middle rows come
    from slices of the cumulative sums, the ends from gathered indices)."""
    x = np.random.default_rng(n).normal(size=(n, 3)) * [1, 2, 3] + 5.0
    half = window // 2
    direct = [x[max(0, i - half) : i + half + 1].var(axis=0).sum() for i in range(n)]
    np.testing.assert_allclose(moving_variance(x, window), direct, rtol=1e-9, atol=1e-12)


def test_moving_variance_and_detection_respect_segments():
    """A segment's windows stop at its boundary, as they stop at the log's ends; no still
    interval spans a boundary, though the readings on both sides agree."""
    rng = np.random.default_rng(8)
    x = rng.normal(scale=0.01, size=(1000, 3)) + np.array([0.0, 0.0, 1.0])
    segment = (np.arange(1000) >= 400).astype(np.int64)
    got = moving_variance(x, 25, segment)
    np.testing.assert_allclose(got[:400], moving_variance(x[:400], 25), rtol=1e-9)
    np.testing.assert_allclose(got[400:], moving_variance(x[400:], 25), rtol=1e-9)
    assert len(detect_still(x, window=25, min_samples=50).segments) == 1
    split = detect_still(x, window=25, min_samples=50, segment=segment).segments
    assert [(s.start <= 400, s.stop <= 400) for s in split] == [(True, True), (False, False)]
    assert split[0].stop == 400 - 6 and split[1].start == 400 + 6  # trimmed at the boundary
    with pytest.raises(InputError, match="one whole number per sample"):
        detect_still(x, window=25, segment=np.zeros(999, dtype=int))


@pytest.mark.parametrize("seed", [1, 3])
def test_a_drifting_gyro_bias_keeps_the_cold_poses(seed: int) -> None:
    """A board warming 20 K moves its gyroscope's bias by ~0.06 rad/s: measured against one
    constant bias the first (cold) poses read as turning; against the bias of the time, every
    pose is found."""
    w = simulate_warmup_log(seed=seed, n_poses=18, span=20.0, drift={"gyro": (3e-3,)})
    c = w.columns
    accel = np.column_stack([c["ax"], c["ay"], c["az"]])
    gyro = np.column_stack([c["gx"], c["gy"], c["gz"]])
    found = detect_still(accel, gyro).segments
    hit = [any(s.start < b and s.stop > a for s in found) for a, b in w.log.segments]
    assert all(hit), f"poses missed: {[i for i, h in enumerate(hit) if not h]}"
    assert len(found) == len(w.log.segments)
