"""The ``matlab`` export (fieldcal.output.exports.matlab): the script's assignments parsed
back give magcal's ``A = inv(gain).'`` and ``b`` exactly, and ``C = (D - b) * A`` is the
calibrated reading."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
from _known import ACCEL_BIAS, ACCEL_GAIN, known_calibration

from fieldcal.output.exports import matlab
from fieldcal.thermal import TemperatureModel


def _assignments(script: str) -> dict[str, np.ndarray]:
    """``NAME = [a b; c d];`` lines as MATLAB reads them (rows split at ``;``)."""
    out = {}
    for name, body in re.findall(r"^(\w+) = \[(.*)\];$", script, flags=re.MULTILINE):
        out[name] = np.array([row.split() for row in body.split(";")], dtype=float)
    return out


def test_script_holds_magcals_matrices_exactly():
    cal = known_calibration(gyro=True)
    values = _assignments(matlab.write(cal))
    assert set(values) == {f"{v}_{s}" for v in "Ab" for s in ("accel", "mag", "gyro")}
    assert np.array_equal(values["A_accel"], np.linalg.inv(ACCEL_GAIN).T)
    assert np.array_equal(values["b_accel"], ACCEL_BIAS[None, :])
    D = np.random.default_rng(9).normal(size=(20, 3)) + ACCEL_BIAS
    C = (D - values["b_accel"]) @ values["A_accel"]
    np.testing.assert_allclose(C, cal.correct_accel(D), rtol=1e-12, atol=1e-15)


def test_temperature_terms_are_assigned_with_their_span():
    cal = known_calibration()
    model = TemperatureModel(20.0, np.array([[0.1, 0.2, 0.3], [1e-3, 0, 0]]), np.array([5.0, 45.0]))
    cal = dataclasses.replace(cal, accel=dataclasses.replace(cal.accel, temperature=model))
    script = matlab.write(cal)
    values = _assignments(script)
    assert values["T_accel"].tolist() == [[20.0, 5.0, 45.0]]
    assert values["c_accel"].tolist() == [[0.1, 0.2, 0.3], [1e-3, 0, 0], [0, 0, 0]]
    assert "T_mag" not in values
    assert matlab.TEMPERATURE_USAGE in script
