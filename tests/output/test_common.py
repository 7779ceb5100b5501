"""What every export writes (fieldcal.output.exports.common): the corrections, exact numbers,
the verdict line and the provenance, with known answers."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from _known import ACCEL_BIAS, ACCEL_GAIN, GYRO_GAIN, MAG_BIAS, MAG_GAIN, known_calibration
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldcal.calibration import Reason, Verdict
from fieldcal.output.exports import common
from fieldcal.thermal import TemperatureModel


def test_corrections_are_inverse_gains_in_sensor_order():
    out = common.corrections(known_calibration(gyro=True))
    assert [name for name, _, _ in out] == ["accel", "mag", "gyro"]
    for (_, M, b), gain, bias in zip(
        out, (ACCEL_GAIN, MAG_GAIN, GYRO_GAIN), (ACCEL_BIAS, MAG_BIAS, None), strict=True
    ):
        np.testing.assert_allclose(M @ gain, np.eye(3), atol=1e-14)
        if bias is not None:
            assert np.array_equal(b, bias)
    assert [n for n, _, _ in common.corrections(known_calibration())] == ["accel", "mag"]


@pytest.mark.parametrize(
    ("gain", "words"),
    [
        (np.zeros((3, 3)), "gain is singular"),
        (np.diag([1.0, np.nan, 1.0]), "not finite"),
        (np.diag([1e-310, 1.0, 1.0]), "overflows a double"),
    ],
)
def test_corrections_refuse_what_has_no_inverse(gain, words):
    cal = known_calibration()
    bad = dataclasses.replace(cal, mag=dataclasses.replace(cal.mag, gain=gain))
    with pytest.raises(ValueError, match=f"the magnetometer's .*{words}"):
        common.corrections(bad)


@settings(max_examples=300, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_exact_reads_back_as_the_same_double_and_never_as_an_integer(x):
    text = common.exact(x)
    assert float(text) == x and np.signbit(float(text)) == np.signbit(x)
    assert "." in text or "e" in text


def test_verdict_line_known_answers():
    cal = known_calibration()
    assert common.verdict_line(cal) == "verdict: none (this calibration was not judged)"
    judged = dataclasses.replace(
        cal,
        verdict=Verdict("warn", (Reason("accuracy", "warn", "a"), Reason("untested", "note", "b"))),
    )
    assert common.verdict_line(judged) == "verdict: WARN (codes: accuracy, untested)"
    plain = dataclasses.replace(cal, verdict=Verdict("pass", ()))
    assert common.verdict_line(plain) == "verdict: PASS (no reasons)"


def test_provenance_names_the_units_and_a_folded_axis_map():
    cal = known_calibration(gyro=True)
    lines = common.provenance(cal)
    assert lines[0].startswith(f"fieldcal {cal.version}, method truth")
    assert lines[1] == common.verdict_line(cal)
    assert lines[2].endswith(", gyroscope rad/s")
    folded = dataclasses.replace(cal, options={"mag_axes": "y,x,-z"})
    assert "axis map y,x,-z is folded in" in common.provenance(folded)[-1]
    assert common.comment_header(cal, "%")[0] == "% Sensor calibration written by fieldcal."


def test_temperature_terms_and_cubic():
    cal = known_calibration()
    assert common.temperature_terms(cal) == []
    linear = TemperatureModel(25.0, np.array([[1.0, 2.0, 3.0]]), np.array([0.0, 50.0]))
    with_terms = dataclasses.replace(cal, mag=dataclasses.replace(cal.mag, temperature=linear))
    assert [n for n, _ in common.temperature_terms(with_terms)] == ["mag"]
    np.testing.assert_array_equal(common.cubic(linear), [[1, 2, 3], [0, 0, 0], [0, 0, 0]])
    quartic = TemperatureModel(25.0, np.ones((4, 3)), np.array([0.0, 50.0]))
    too_high = dataclasses.replace(cal, mag=dataclasses.replace(cal.mag, temperature=quartic))
    with pytest.raises(ValueError, match="order 4; the exports hold at most 3"):
        common.temperature_terms(too_high)
