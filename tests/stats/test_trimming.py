"""Unsteady samples cut within poses (fieldcal.stats.trimming): the cut against a plain
reimplementation of the module's rule (per-pose medians, the pooled MAD scale, d² beyond CUT,
small poses and mostly-unsteady poses kept whole), on poses small and large."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.stats.trimming import CUT, MIN_SAMPLES, SELECT, trim_unsteady


def _reference_cut(stacked: np.ndarray, counts: np.ndarray) -> np.ndarray:
    starts = np.cumsum(counts) - counts
    poses = [stacked[s : s + c] for s, c in zip(starts, counts, strict=True)]
    medians = [np.median(p, axis=0) for p in poses]
    eligible = counts >= MIN_SAMPLES
    mads = np.array([np.median(np.abs(p - m), axis=0) for p, m in zip(poses, medians, strict=True)])
    scale = 1.4826 * np.median(mads[eligible], axis=0)
    cut = np.zeros(len(stacked), dtype=bool)
    for i, (p, m, s) in enumerate(zip(poses, medians, starts, strict=True)):
        if not eligible[i]:
            continue
        beyond = np.sum(((p - m) / scale) ** 2, axis=1) > CUT
        if beyond.sum() <= counts[i] // 2:
            cut[s : s + counts[i]] = beyond
    return cut


def _session(counts: list[int], seed: int, bumps: int = 5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    poses = []
    for c in counts:
        p = rng.normal(size=3) * 10 + rng.normal(scale=0.01, size=(c, 3))
        hit = rng.choice(c, size=min(bumps, c), replace=False)
        p[hit] += rng.normal(scale=0.2, size=(len(hit), 3))  # taps of about 20 sigma
        poses.append(p)
    return np.concatenate(poses)


@pytest.mark.parametrize(
    "counts",
    [[50, 60, 40, 80], [5, 30, 200, 9, 11], [SELECT + 100, 40, SELECT * 2, 25]],
)
def test_the_cut_is_the_rule_written_plainly(counts):
    counts = np.array(counts)
    x = _session(list(counts), seed=int(counts.sum()))
    expected = _reference_cut(x, counts)
    kept, kept_counts, trimmed = trim_unsteady(x, counts)
    np.testing.assert_array_equal(kept, x[~expected])
    starts = np.cumsum(counts) - counts
    np.testing.assert_array_equal(
        trimmed, [expected[s : s + c].sum() for s, c in zip(starts, counts, strict=True)]
    )
    np.testing.assert_array_equal(kept_counts, counts - trimmed)
    assert trimmed.sum() > 0  # the taps are found
    assert np.all(trimmed[counts < MIN_SAMPLES] == 0)


def test_still_poses_are_returned_as_they_are():
    counts = np.array([100, 100, 100])
    x = np.random.default_rng(3).normal(scale=0.01, size=(300, 3))
    kept, kept_counts, trimmed = trim_unsteady(x, counts)
    assert kept is x and kept_counts is counts and not trimmed.any()


def test_a_pose_mostly_unsteady_is_kept_whole():
    rng = np.random.default_rng(4)
    calm = [rng.normal(scale=0.01, size=(60, 3)) for _ in range(4)]
    shaken = rng.normal(scale=1.0, size=(60, 3))
    x = np.concatenate([*calm, shaken])
    counts = np.full(5, 60)
    _, _, trimmed = trim_unsteady(x, counts)
    assert trimmed[4] == 0
    np.testing.assert_array_equal(trimmed, _reference_counts(x, counts))


def _reference_counts(x, counts):
    cut = _reference_cut(x, counts)
    starts = np.cumsum(counts) - counts
    return [int(cut[s : s + c].sum()) for s, c in zip(starts, counts, strict=True)]


def test_a_quantised_sensor_with_no_scatter_is_not_trimmed():
    x = np.repeat(np.array([[1.0, 2.0, 3.0]]), 200, axis=0)
    x[17] += 5.0
    kept, _, trimmed = trim_unsteady(x, np.array([100, 100]))
    assert not trimmed.any() and len(kept) == 200
