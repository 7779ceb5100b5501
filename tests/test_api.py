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


@pytest.mark.parametrize("factor", [1e-30, 3.7e-5, 1.0e4, 1e30])
def test_results_are_scale_invariant_over_the_float_range(factor):
    """Readings in any unit: everything scales with them, angles and verdicts do not move."""
    s = fieldcal.simulate("paper", seed=3)
    base = fieldcal.calibrate(s.accel, s.mag)
    cal = fieldcal.calibrate([a * factor for a in s.accel], [m * factor for m in s.mag])
    assert cal.dip_deg == pytest.approx(base.dip_deg, abs=1e-10)
    assert cal.dip_std_deg == pytest.approx(base.dip_std_deg, rel=1e-9)
    np.testing.assert_allclose(cal.accel.gain / factor, base.accel.gain, rtol=1e-10)
    np.testing.assert_allclose(cal.mag.bias / factor, base.mag.bias, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(cal.mag.gain_std / factor, base.mag.gain_std, rtol=1e-8)
    np.testing.assert_allclose(cal.accel.noise_cov / factor**2, base.accel.noise_cov, rtol=1e-9)
    assert cal.mag.pose_noise_std / factor == pytest.approx(base.mag.pose_noise_std, abs=1e-12)
    assert cal.accuracy.tilt_deg == pytest.approx(base.accuracy.tilt_deg, rel=1e-8)
    assert cal.verdict == base.verdict and cal.rejected == base.rejected
    assert fieldcal.Calibration.from_json(cal.to_json()) == cal


def test_readings_too_large_to_square_are_one_line_errors():
    s = fieldcal.simulate("paper", seed=3)
    with pytest.raises(ValueError, match="too large to square") as info:
        fieldcal.calibrate([a * 1e300 for a in s.accel], s.mag)
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match="too large to square"):
        fieldcal.calibrate(s.accel, s.mag, noise=1e300)
