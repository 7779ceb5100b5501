"""What both autopilot exports share (fieldcal.output.exports.autopilot): units read from the
field's size, the symmetric compass matrix and the misalignment it drops (a known rotation),
the per-axis accelerometer's error bound, and the ranges."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from _known import ACCEL_GAIN, MAG_GAIN, G, known_calibration

from fieldcal.errors import InputError
from fieldcal.output.exports import autopilot as ap


@pytest.mark.parametrize(
    ("strength", "unit", "factor"),
    [(48.5, "mG", 10.0), (0.485, "mG", 1000.0), (485.0, "G", 1e-3), (48500.0, "G", 1e-5)],
)
def test_field_units_are_read_from_the_size(strength, unit, factor):
    cal = known_calibration().with_field_magnitudes(field_strength=strength)
    assert ap.mag_factor(cal, unit) == pytest.approx(factor, rel=1e-12)


def test_a_field_not_earths_or_not_scaled_is_refused():
    with pytest.raises(InputError, match="field strength 5 is not Earth's field"):
        ap.mag_factor(known_calibration().with_field_magnitudes(field_strength=5.0), "G")
    with pytest.raises(InputError, match="not scaled to a field strength"):
        unit = dataclasses.replace(known_calibration(), magnetic=np.array([0.6, 0.0, 0.8]))
        ap.mag_factor(unit, "G")  # |h| = 1: the default, unscaled


def test_gravity_units():
    cal = known_calibration()
    assert ap.accel_factor(cal) == 1.0
    assert ap.accel_factor(cal.with_field_magnitudes(gravity=1.0)) == ap.STANDARD_GRAVITY
    with pytest.raises(InputError, match="gravity 3 is neither g"):
        ap.accel_factor(cal.with_field_magnitudes(gravity=3.0))


def test_a_rotated_magnetometer_drops_exactly_its_rotation():
    angle = np.radians(5.0)
    c, s = np.cos(angle), np.sin(angle)
    U = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    cal = known_calibration()
    rotated = dataclasses.replace(cal, mag=dataclasses.replace(cal.mag, gain=MAG_GAIN @ U))
    out = ap.autopilot(rotated, "mG")
    assert out.misalignment_deg == pytest.approx(5.0, abs=1e-9)
    # the symmetric part is kept: M = 10 mG/µT x inv(P), P = MAG_GAIN
    np.testing.assert_allclose(out.mag_matrix, 10 * np.linalg.inv(MAG_GAIN), rtol=1e-12)
    assert np.array_equal(out.mag_matrix, out.mag_matrix.T)


def test_accel_error_bound_is_the_largest_per_axis_error_at_one_g():
    out = ap.autopilot(known_calibration(), "mG")
    # brute force over directions: |diag(1/d) P u - u| * g for unit u, maximised
    u = np.random.default_rng(3).normal(size=(20000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    err = (u @ ACCEL_GAIN.T) / np.diag(ACCEL_GAIN) - u
    brute = G * np.linalg.norm(err, axis=1).max()
    assert brute <= out.accel_error_bound * (1 + 1e-12)
    assert brute == pytest.approx(out.accel_error_bound, rel=1e-3)
    assert f"{out.accel_error_bound:.6g} m/s²" in ap.accel_error_text(out)


def test_mirrored_magnetometer_is_refused():
    cal = known_calibration()
    mirrored = dataclasses.replace(
        cal, mag=dataclasses.replace(cal.mag, gain=MAG_GAIN @ np.diag([1.0, 1.0, -1.0]))
    )
    with pytest.raises(InputError, match="mirrored relative to the accelerometer's"):
        ap.autopilot(mirrored, "G")
    only = dataclasses.replace(cal, mag=None)
    with pytest.raises(InputError, match="need both the accelerometer and the magnetometer"):
        ap.autopilot(only, "G")


def test_parameter_range_bounds():
    strict = ap.ParameterRange("A_{}", 0.2, 5.0, True, "src")
    closed = ap.ParameterRange("B_{}", -1.0, None, False, "src")
    assert [strict.accepts(v) for v in (0.2, 0.21, 4.99, 5.0, np.nan)] == [
        False, True, True, False, False,
    ]  # fmt: skip
    assert closed.accepts(-1.0) and not closed.accepts(-1.01) and not closed.accepts(np.inf)
    assert (strict.text(), closed.text()) == ("(0.2, 5)", ">= -1")
    params = [("A_X", 1.0), ("A_Y", 7.0), ("A_Z", 0.1)]
    with pytest.raises(
        InputError,
        match=r"A_Y = 7 is outside the range T accepts, \(0\.2, 5\) \(src\) \(and 1 more\)",
    ):
        ap.check_ranges(params, (strict,), "T", allow_out_of_range=False)
    outside = ap.check_ranges(params, (strict,), "T", allow_out_of_range=True)
    assert list(outside) == ["A_Y", "A_Z"]
    lines = ap.parameter_lines(params, outside, lambda n, v: f"{n}={v}")
    assert lines[0] == "A_X=1.0" and lines[1].startswith("# OUT OF RANGE") and lines[2] == "A_Y=7.0"
