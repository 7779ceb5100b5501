"""What apply needs whatever the format: the columns found, the refusals naming the fix, the
temperature terms' inputs checked, values written as the shortest text that reads back."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.errors import InputError
from fieldcal.logs.calibrated_columns import (
    SHOWN,
    Thermal,
    as_text,
    check_new_columns,
    columns_for_apply,
    shown_header,
)


def test_columns_are_named_or_recognised():
    header = ["t", "ax", "ay", "az", "acc_1", "acc_2", "acc_3"]
    none = {"accel": None, "mag": None}
    assert columns_for_apply("log", header, ["accel", "mag"], none) == {"accel": ["ax", "ay", "az"]}
    named = {"accel": "acc_1,acc_2,acc_3", "mag": None}
    assert columns_for_apply("log", header, ["accel"], named) == {
        "accel": ["acc_1", "acc_2", "acc_3"]
    }
    with pytest.raises(InputError, match="no column 'acc_4'"):
        columns_for_apply("log", header, ["accel"], {"accel": "acc_1,acc_2,acc_4"})
    with pytest.raises(InputError, match="pass --accel-cols/--mag-cols/--gyro-cols"):
        columns_for_apply("log", ["t", "x"], ["accel", "mag"], none)


def test_a_long_or_binary_header_is_shown_short_and_escaped():
    text = shown_header(["\x00" * 10_000])
    assert len(text) < SHOWN + 40 and "\x00" not in text and text.endswith("(1 column(s))")
    assert shown_header(["ax", "ay"]) == "ax, ay"


def test_a_log_calibrated_before_is_refused():
    check_new_columns("log", ["ax"], ["ax_cal"])
    with pytest.raises(InputError, match="already has the column 'ax_cal'"):
        check_new_columns("log", ["ax", "ax_cal"], ["ax_cal"])


def test_values_read_back_as_the_same_value_of_their_type():
    rng = np.random.default_rng(1)
    doubles = rng.normal(size=50) * 10.0 ** rng.integers(-20, 20, 50)
    assert np.array_equal(np.array([float(s) for s in as_text(doubles)]), doubles)
    singles = doubles.astype(np.float32)
    assert np.array_equal(np.array(as_text(singles), dtype=np.float32), singles)
    assert as_text(np.array(["a", None], dtype=object)) == ["a", ""]


def test_the_temperature_inputs_are_checked():
    with pytest.raises(InputError, match="temp_col must be a column name"):
        Thermal(None, [], 3, None)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="temperature must be a number"):
        Thermal(None, [], None, float("nan"))  # type: ignore[arg-type]
    thermal = Thermal(None, [], None, 21.5)  # type: ignore[arg-type]
    assert thermal.values(None) == 21.5
    with pytest.raises(InputError, match="not a finite number"):
        thermal.values(np.array([20.0, np.nan]), "temp")
