"""Readings divided by an exact power of two (fieldcal.stats.scaling): the same digits back,
readings of order one, one-line refusals beyond the range."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.stats.scaling import normalise


def test_a_continuous_array_is_brought_to_order_one_exactly():
    x = np.random.default_rng(1).normal(scale=3e4, size=(200, 3))  # 16-bit counts
    scaled, scale = normalise(x, "accel")
    assert scale == 2.0 ** round(np.log2(np.abs(x).max()))
    assert 0.5 <= np.abs(scaled).max() <= 2.0
    np.testing.assert_array_equal(scaled * scale, x)  # bit for bit


def test_per_pose_input_is_scaled_by_its_largest_reading():
    rng = np.random.default_rng(2)
    poses = [rng.normal(scale=5e-5, size=(n, 3)) for n in (5, 9, 7)]  # tesla
    scaled, scale = normalise(poses, "mag")
    largest = max(np.abs(p).max() for p in poses)
    assert scale == 2.0 ** round(np.log2(largest))
    for p, q in zip(poses, scaled, strict=True):
        np.testing.assert_array_equal(q * scale, p)


def test_order_one_and_missing_input_are_left_alone():
    poses = [np.full((3, 3), 0.9)]
    scaled, scale = normalise(poses, "accel")
    assert scale == 1.0 and scaled is not None and scaled[0] is poses[0]
    assert normalise(None, "mag") == (None, 1.0)
    zeros, scale = normalise(np.zeros((4, 3)), "accel")
    assert scale == 1.0 and np.array_equal(zeros, np.zeros((4, 3)))


def test_readings_too_large_to_square_are_refused_naming_the_sample():
    x = np.ones((5, 3))
    x[3, 1] = 1e200
    with pytest.raises(ValueError, match=r"accel: readings up to 1e\+200 \(sample 3, axis y\)"):
        normalise(x, "accel")
