"""What an option is: a Range checks a number's text, an Option's manifest column follows its
flag, meta declares a field's option; the settings table is made of them."""

from __future__ import annotations

import math

import pytest

from fieldcal import settings
from fieldcal.option_types import MAGNITUDE, POSITIVE, Option, Range, library_only, meta


def test_a_range_checks_the_text_of_a_number():
    assert Range(0.0, 10.0).check("2.5") == 2.5
    with pytest.raises(ValueError, match="above 0 and at most 10"):
        Range(0.0, 10.0).check("0")
    assert Range(0.0, 10.0, low_open=False).check("0") == 0.0
    for bad in ("nan", "inf", "x"):
        with pytest.raises(ValueError):
            POSITIVE.check(bad)
    assert MAGNITUDE.check("1e-3") == 1e-3 and not math.isnan(MAGNITUDE.check("1"))


def test_an_options_column_and_old_spelling_follow_its_flag():
    option = Option("--still-trim/--no-trim", "help", old_flag="--trim")
    assert option.column == "still_trim" and option.old_column == "trim"
    assert option.on_command_line and not library_only("help")["option"].on_command_line
    assert meta("--rate", "Hz", unit="Hz")["option"] == Option("--rate", "Hz", unit="Hz")


def test_the_table_is_made_of_these_options():
    assert settings.Option is Option and settings.Range is Range
    assert all(isinstance(o, Option) for o in settings.OPTIONS.values())
