"""An option's text parsed: for both sensors or per sensor, the World Magnetic Model's keyword
in its spellings, a flag's words; a bad value refused with its reason."""

from __future__ import annotations

import pytest

from fieldcal.errors import NOT_A_SENSOR, InputError
from fieldcal.option_text import (
    WMM_UNITS,
    parse_field_strength,
    parse_flag,
    parse_noise,
    parse_pose_noise,
    wmm_unit,
)


def test_noise_for_both_sensors_or_each():
    assert parse_noise("0.01") == 0.01
    assert parse_noise("accel=0.01, MAG=0.2") == {"accel": 0.01, "mag": 0.2}
    with pytest.raises(InputError, match="'gyro' is not a sensor") as refused:
        parse_noise("gyro=0.1")
    assert refused.value.code == NOT_A_SENSOR
    with pytest.raises(ValueError, match="out of range"):
        parse_noise("-1")


def test_pose_noise_words_numbers_and_sensors():
    assert parse_pose_noise(" Auto ") == "auto" and parse_pose_noise("0") == 0.0
    assert parse_pose_noise("accel=0.01,mag=none") == {"accel": 0.01, "mag": "none"}


def test_the_world_magnetic_model_keyword_is_parsed_once():
    assert {wmm_unit(k.replace("wmm", "WMM")) for k in WMM_UNITS} == {"uT", "nT", "G", "mG"}
    assert wmm_unit("50") is None and wmm_unit(50.0) is None
    assert parse_field_strength(" wmm:nT ") == "wmm:nT"
    assert wmm_unit("wmm:gauss") == "G" and wmm_unit("WMM:mGauss") == "mG"  # flight logs' units
    assert parse_field_strength("48.5") == 48.5
    with pytest.raises(ValueError, match="neither a number nor wmm"):
        parse_field_strength("earth")


@pytest.mark.parametrize(
    ("text", "value"), [("yes", True), ("ON", True), ("0", False), ("n", False)]
)
def test_flags(text, value):
    assert parse_flag(text) is value


def test_a_flag_word_not_known_is_refused():
    with pytest.raises(ValueError, match="give true or false"):
        parse_flag("maybe")
