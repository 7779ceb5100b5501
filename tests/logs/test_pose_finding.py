"""Poses of slow continuous logs without a gyroscope: one per sample (``poses="samples"``), the
motion check at a high percentile, window advice that the same check accepts, and the
correlation between neighbouring poses measured for the error bars."""

from __future__ import annotations

import re

import numpy as np
import pytest
from _logs import _csv, _turning

from fieldcal.errors import InputError
from fieldcal.logs import load_log
from fieldcal.logs.pose_finding import MAX_SAMPLE_POSES, MOTION_LIMIT, poses_from_log
from fieldcal.trust.correlation import measure_correlation


def _sparse(columns, every):
    """Every ``every``-th row, without the time column (Magneto's logs have none)."""
    return {k: v[::every] for k, v in columns.items() if k != "t"}


def test_a_sparse_log_without_time_is_one_pose_per_sample(tmp_path):
    columns, _ = _turning(3, seconds=120.0, speed_deg=20.0)
    log = load_log(_csv(tmp_path / "sparse.csv", _sparse(columns, 33)))  # ~3 rows/s
    assert log.time is None
    poses = poses_from_log(log, poses="samples")
    assert poses.source == "samples" and poses.n == log.n and poses.time_ordered
    assert all(e["samples"] == 1 and e["std"] is None for e in poses.entries)
    assert [e["start"] for e in poses.entries] == list(range(log.n))
    assert poses.record() == {"source": "samples", "samples_per_pose": 1, "rate_hz": None}
    # "windows" refuses such a log: a default window would be 25 samples = 8 s of turning
    with pytest.raises(InputError):
        poses_from_log(log, poses="windows")


def test_a_dense_log_is_grouped_into_short_windows(tmp_path):
    columns, _ = _turning(4, seconds=90.0, speed_deg=12.0)  # 9000 rows at 100 Hz
    log = load_log(_csv(tmp_path / "dense.csv", columns))
    poses = poses_from_log(log, poses="samples")
    assert poses.source == "samples" and poses.n <= MAX_SAMPLE_POSES
    assert poses.record()["samples_per_pose"] == 3  # ceil(9000 / 3000)
    assert sum(e["samples"] for e in poses.entries) == log.n


def _half_rest(tmp_path, speed_deg):
    """20 s still, then 20 s turning fast."""
    columns, _ = _turning(5, seconds=20.0, speed_deg=speed_deg)
    still, _ = _turning(5, seconds=20.0, speed_deg=0.0)
    joined = {
        k: np.concatenate([still[k], columns[k] + (20.0 if k == "t" else 0.0)]) for k in columns
    }
    return load_log(_csv(tmp_path / "half.csv", joined))


def test_a_half_rest_log_does_not_pass_the_motion_check_at_zero(tmp_path):
    log = _half_rest(tmp_path, 90.0)
    with pytest.raises(InputError, match=r"moves too fast for 0\.25 s windows") as info:
        poses_from_log(log, poses="windows")
    text = str(info.value)
    moved = float(re.search(r"moves ([\d.]+)% of \|g\|", text)[1]) / 100
    # the fast half's motion (a 0.25 s window sweeps ~22° at 90°/s), not the rests' 0 %
    assert moved > 2 * MOTION_LIMIT and "90th percentile" in text
    rate = float(re.search(r"turns up to ([\d.]+)°/s", text)[1])
    assert 45.0 < rate < 180.0  # the direction's rate of change, from the windows


@pytest.mark.parametrize("speed", [60.0, 100.0])
def test_the_suggested_window_is_accepted_on_the_same_log(tmp_path, speed):
    columns, _ = _turning(6, seconds=20.0, speed_deg=speed)
    log = load_log(_csv(tmp_path / "fast.csv", columns))
    with pytest.raises(InputError, match="moves too fast") as info:
        poses_from_log(log, poses="windows")
    shorter = float(re.search(r"give --window ([\d.]+) \(seconds\)", str(info.value))[1])
    assert shorter < 0.25
    poses = poses_from_log(log, poses="windows", window=shorter)
    assert poses.windows.motion <= MOTION_LIMIT and poses.windows.seconds == pytest.approx(shorter)


def test_too_fast_for_any_window_points_to_samples(tmp_path):
    columns, _ = _turning(6, seconds=20.0, speed_deg=400.0)
    log = load_log(_csv(tmp_path / "faster.csv", columns))
    with pytest.raises(InputError, match=r"use --poses samples") as info:
        poses_from_log(log, poses="windows")
    assert "give --window" not in str(info.value)
    assert poses_from_log(log, poses="samples").n == 2000  # ceil(2000 / 3000) = 1 per pose


def test_the_correlation_of_an_ar1_series_is_measured():
    rng = np.random.default_rng(7)
    phi, n = 0.8, 20000
    x = np.zeros((n, 3))
    e = rng.standard_normal((n, 3))
    for k in range(1, n):
        x[k] = phi * x[k - 1] + e[k]
    found = measure_correlation(x)
    tau = (1 + phi) / (1 - phi)  # 9: the variance of a mean is 9x that of independent terms
    # Sokal's window leaves a bias of about τ·ρ^M ~ 1 %; the estimate's own spread ~ 5 %
    assert found.tau == pytest.approx(tau, rel=0.15) and found.reached
    assert found.effective == pytest.approx(n / found.tau)
    white = measure_correlation(rng.standard_normal((n, 3)))
    assert white.tau == pytest.approx(1.0, abs=0.1) and white.widening == pytest.approx(
        1.0, abs=0.05
    )
