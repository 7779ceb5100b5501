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
    # the same verdict, but for the warning that no unit explains the scale (issue 35, S3):
    # 1e4 is a unit (counts), 3.7e-5 (an accelerometer unit of 27,000 g), 1e±30 are none
    kept = tuple(r for r in cal.verdict.reasons if r.code != "unexplained_scale")
    assert kept == base.verdict.reasons and cal.rejected == base.rejected
    assert (len(kept) < len(cal.verdict.reasons)) == (factor != 1.0e4)
    assert fieldcal.Calibration.from_json(cal.to_json()) == cal


def test_readings_too_large_to_square_are_one_line_errors():
    s = fieldcal.simulate("paper", seed=3)
    with pytest.raises(ValueError, match="too large to square") as info:
        fieldcal.calibrate([a * 1e300 for a in s.accel], s.mag)
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match="too large to square"):
        fieldcal.calibrate(s.accel, s.mag, noise=1e300)


def _session():
    s = fieldcal.simulate("paper", seed=3, n_poses=10, samples=(20, 40))
    return list(s.accel), list(s.mag)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda p: [x + 0.01j for x in p], "pose 0 holds complex numbers"),
        (lambda p: [x.astype(complex) for x in p], "pose 0 holds complex numbers"),
        (lambda p: [x.astype(str) for x in p], "pose 0 holds text"),
        (lambda p: [x > 0 for x in p], "pose 0 holds true/false values"),
        (lambda p: [*p[:3], None, *p[4:]], "pose 3 is not numeric"),
        (lambda p: [*p[:3], p[3][:, :2], *p[4:]], r"pose 3 has shape \(\d+, 2\)"),
        (lambda p: [[x.tolist()] for x in p], r"pose 0 has shape \(1, \d+, 3\)"),
        (lambda p: [[*x.tolist()[:2], [1.0, 2.0]] for x in p], "pose 0 is not an array"),
        (lambda p: np.array(p, dtype=object), "expected a sequence of per-pose"),
        (lambda p: [np.ma.masked_array(x, x > 0) for x in p], "masked entries"),
        (lambda p: "accel.csv", "expected a sequence of per-pose"),
        (lambda p: (x for x in p), "expected a sequence of per-pose"),
        (lambda p: [x * 1e300 for x in p], r"readings up to .* \(pose \d+, sample \d+, axis"),
    ],
)
def test_what_is_not_readings_is_refused_in_one_line(change, message):
    import warnings

    accel, mag = _session()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a ComplexWarning would mean a silent truncation
        with pytest.raises(ValueError, match=message) as info:
            fieldcal.calibrate(change(accel), mag)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("method", ["ellipsoid", "mle"])
def test_continuous_input_of_the_wrong_kind(method):
    accel, _ = _session()
    stacked = np.concatenate(accel)
    for bad, message in [
        (stacked.astype(str), "holds text"),
        (stacked + 0j, "holds complex numbers"),
        (stacked > 0, "true/false"),
    ]:
        with pytest.raises(ValueError, match=message):
            fieldcal.calibrate(bad, None, method=method)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"gravity": "9.8"}, "gravity must be a positive number, got '9.8'"),
        ({"gravity": 1e300}, "gravity must be a positive number from 1e-150 to 1e150"),
        ({"field_strength": np.array([48.0, 1.0])}, "field_strength must be a positive number"),
        ({"initial": "cal.json"}, "initial must be a fieldcal.Calibration"),
        ({"max_iter": 0}, "max_iter must be a whole number of at least 1"),
        ({"max_iter": 2.5}, "max_iter must be a whole number"),
        ({"tol": float("nan")}, "tol must be a positive finite number"),
        ({"tol": "1e-9"}, "tol must be a positive finite number"),
        ({"mag_mirrored": "yes"}, "mag_mirrored must be True or False"),
        ({"robust": 1}, "robust must be True or False"),
        ({"cut_unsteady": "no"}, "cut_unsteady must be True or False"),
        ({"false_alarm": 0}, r"false_alarm must be in \(0, 1\)"),
        ({"on_progress": "print"}, "on_progress must be a function"),
        ({"noise": np.eye(3) * 1j}, "noise for accel must be a number or an array of real"),
        ({"noise": 1e-200}, "noise for accel is too small to square"),
        ({"noise": np.ones((3, 3)) * 2}, "positive definite"),
        ({"pose_noise": float("inf")}, "pose_noise for accel must be finite"),
        ({"method": "ellipsoid", "inclination_deg": "60"}, "inclination_deg must be a number"),
        ({"method": "ellipsoid", "faithful": "yes"}, "faithful must be True or False"),
        ({"method": "greedy", "gamma": float("nan")}, "gamma must be a positive number"),
        ({"method": "greedy", "max_iterations": 0}, "max_iterations must be a whole number"),
    ],
)
def test_options_are_checked_as_values(kwargs, message):
    accel, mag = _session()
    with pytest.raises(ValueError, match=message) as info:
        fieldcal.calibrate(accel, mag, **kwargs)
    assert "\n" not in str(info.value) and len(str(info.value)) < 300


def test_degenerate_input_never_shows_numpy_errors():
    """LinAlgError ("Singular matrix") and RuntimeWarnings stay inside: one-line reasons."""
    import warnings

    accel, mag = _session()
    cases = [
        ([np.ones((20, 3))] * 10, mag),  # constant readings
        ([np.outer(np.arange(1, 21.0), [1, 2, 3]) * k for k in range(1, 11)], mag),  # a line
        (accel, [np.full((20, 3), 1e-310)] * 10),  # subnormal
    ]
    for a, m in cases:
        for method in ("mle", "ellipsoid", "greedy"):
            with warnings.catch_warnings():
                warnings.simplefilter("error", RuntimeWarning)
                try:
                    cal = fieldcal.calibrate(a, m, method=method)
                except np.linalg.LinAlgError:  # a ValueError too, but numpy's words
                    pytest.fail(f"{method}: LinAlgError escaped")
                except ValueError as exc:
                    assert "\n" not in str(exc)
                else:
                    cal.check_values()


def test_the_old_trim_keyword_is_taken_with_a_deprecation_warning():
    """``trim=`` (the fit's cut of unsteady samples) is now ``cut_unsteady=``: the old name
    gives the same calibration, with a DeprecationWarning; both at once is an error."""
    s = fieldcal.simulate("paper", seed=2)
    new = fieldcal.calibrate(s.accel, s.mag, cut_unsteady=False)
    with pytest.warns(DeprecationWarning, match="trim= is now cut_unsteady="):
        old = fieldcal.calibrate(s.accel, s.mag, trim=False)
    assert old == new and old.options["trim"] is False
    with pytest.raises(ValueError, match="both given"):
        fieldcal.calibrate(s.accel, s.mag, trim=False, cut_unsteady=True)
