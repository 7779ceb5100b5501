"""The units of the readings: a name or a number given, the column names, the calibration's."""

from __future__ import annotations

import math

import pytest

import fieldcal
from fieldcal.errors import InputError
from fieldcal.reading_units import (
    STANDARD_GRAVITY,
    UNITS,
    calibration_unit,
    column_unit,
    option_unit,
)


def test_a_unit_option_by_name_alias_or_number():
    assert option_unit("g", "accel") == ("g", STANDARD_GRAVITY)
    assert option_unit("m/s²", "accel") == ("m/s^2", 1.0)
    assert option_unit(" DPS ", "gyro") == ("deg/s", math.pi / 180)
    assert option_unit(None, "gyro") is None
    unit, factor = option_unit(0.001, "accel")
    assert unit == "raw" and factor == 0.001
    with pytest.raises(InputError, match="accel_unit must be one of g, mg, m/s"):
        option_unit("furlong", "accel")
    with pytest.raises(InputError, match="outside any sensor's raw unit"):
        option_unit(1e6, "gyro")


def test_column_names_that_state_a_unit():
    assert column_unit(["ax_g", "ay_g", "az_g"], "accel") == "g"
    assert column_unit(["acc_x_m_s_2"], "accel") == "m/s^2"
    assert column_unit(["gx_dps", "gy_dps", "gz_dps"], "gyro") == "deg/s"
    assert column_unit(["ax", "ay", "az"], "accel") is None
    assert set(UNITS) == {"accel", "gyro"}


def test_a_calibration_gives_its_units():
    s = fieldcal.simulate("paper", seed=1)
    cal = fieldcal.calibrate(s.accel, s.mag)
    unit, factor = calibration_unit(cal, "accel")
    assert unit == "g" and factor == STANDARD_GRAVITY  # unit fields: |g| = 1
    si = fieldcal.calibrate(s.accel, s.mag, gravity=STANDARD_GRAVITY)
    assert calibration_unit(si, "accel") == ("m/s^2", 1.0)
