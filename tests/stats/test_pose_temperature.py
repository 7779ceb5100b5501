"""Each pose's mean temperature (fieldcal.stats.pose_temperature): means, reference, powers and
subsets as known answers; implausible or malformed temperatures refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.stats.pose_temperature import PoseTemperature, pose_temperatures


def test_means_reference_span_and_powers():
    means = pose_temperatures([[20.0, 22.0], np.array([30.0]), [40.0, 41.0, 42.0]], 3)
    np.testing.assert_array_equal(means, [21.0, 30.0, 41.0])
    pt = PoseTemperature(means, {"accel": 2, "mag": 0})
    assert pt.reference == pytest.approx(92.0 / 3)
    np.testing.assert_array_equal(pt.span, [21.0, 41.0])
    assert pt.orders == {"accel": 2} and pt.order("mag") == 0 and pt.order("accel") == 2
    d = means - 92.0 / 3
    np.testing.assert_allclose(pt.powers(2), np.column_stack([d, d**2]), rtol=1e-14)
    assert pt.powers(0).shape == (3, 0)


def test_a_subset_moves_the_reference_with_the_poses_kept():
    pt = PoseTemperature(np.array([10.0, 20.0, 60.0]), {"mag": 1})
    sub = pt.subset([0, 1])
    assert sub.reference == 15.0 and sub.orders == {"mag": 1}
    again = pt.with_orders({"accel": 3}, refused=True)
    assert again.orders == {"accel": 3} and again.refused and again.reference == pt.reference


@pytest.mark.parametrize(
    ("temperature", "n", "words"),
    [
        ("25", 1, "one array of samples"),
        ([[20.0]], 2, "temperature has 1 poses but the readings have 2"),
        ([[20.0], []], 2, "pose 1 is empty"),
        ([[20.0], [np.nan]], 2, "pose 1 is empty or has NaN"),
        ([[20.0], ["warm"]], 2, "pose 1 is not an array of numbers"),
        ([[20.0], [300.0]], 2, "outside -80..200 °C"),
    ],
)
def test_refusals(temperature, n, words):
    with pytest.raises(ValueError, match=words) as info:
        pose_temperatures(temperature, n)
    assert "\n" not in str(info.value)
