"""Input checks of fieldcal.calibrate shared by every method."""

import numpy as np
import pytest

import fieldcal


def _poses(n, rng=None):
    rng = rng or np.random.default_rng(0)
    return [rng.normal(size=(20, 3)) for _ in range(n)]


@pytest.mark.parametrize("method", ["mle", "greedy"])
def test_fewer_than_eight_poses_is_refused_with_the_reason(method):
    with pytest.raises(ValueError, match="needs at least 8") as info:
        fieldcal.calibrate(_poses(7), _poses(7), method=method)
    assert "3N rotation angles plus 22" in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"method": "magic"}, "unknown method 'magic'"),
        ({"body_frame": "gyro"}, "body_frame must be"),
        ({"noise": [1.0, 2.0]}, "standard deviation .* or a 3x3"),
        ({"noise": -1.0}, "finite and positive"),
        ({"noise": {"gyro": 1.0}}, "noise keys"),
    ],
)
def test_bad_options_are_one_line_value_errors(kwargs, message):
    with pytest.raises(ValueError, match=message) as info:
        fieldcal.calibrate(_poses(9), _poses(9), **kwargs)
    assert "\n" not in str(info.value)


def test_mismatched_pose_counts_and_nan_are_refused():
    with pytest.raises(ValueError, match="accel has 9 poses but mag has 10"):
        fieldcal.calibrate(_poses(9), _poses(10))
    bad = _poses(9)
    bad[4][3, 1] = np.nan
    with pytest.raises(ValueError, match=r"mag: NaN or inf readings in 1 pose\(s\) \(4\)"):
        fieldcal.calibrate(_poses(9), bad)
