"""A reader's table (fieldcal.logs.raw_table): to_float is Python's float on every cell a reader
takes for a number, names the first bad cell and its row; numeric columns by dtype."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldcal.errors import InputError
from fieldcal.logs.raw_table import Table, to_float


@settings(max_examples=200, deadline=None)
@given(
    cells=st.lists(
        st.one_of(
            st.floats(allow_nan=False).map(repr),
            st.integers(-(10**6), 10**6).map(str),
            st.sampled_from(["", " ", " 1.5 ", "-0", "1e-320"]),
        ),
        min_size=1,
        max_size=20,
    )
)
def test_to_float_is_python_float_on_every_cell(cells):
    got = to_float(np.array(cells), "ax", "log.csv")
    expected = [float(c) if c.strip() else math.nan for c in cells]
    assert np.array_equal(got, np.array(expected), equal_nan=True)
    assert np.array_equal(np.signbit(got), np.signbit(expected))


def test_to_float_names_the_first_bad_cell_and_its_row():
    with pytest.raises(
        InputError, match=r"column 'ax' has a non-numeric value 'x1' at data row 12"
    ):
        to_float(np.array(["1", "2", "x1", "y"]), "ax", "log.csv", first_row=9)
    # '1_000' and full-width digits are float() input but no reader's number
    for cell in ("1_000", "\uff11"):
        with pytest.raises(InputError, match="data row 2"):
            to_float(np.array(["1", cell]), "ax", "log.csv")


def test_to_float_with_decimal_commas_refuses_points():
    assert to_float(np.array(["1,5", "-0,25", ""]), "a", "p", decimal=",").tolist()[:2] == [
        1.5,
        -0.25,
    ]
    with pytest.raises(InputError, match=r"non-numeric value '1\.234,5' at data row 1"):
        to_float(np.array(["1.234,5"]), "a", "p", decimal=",")


def test_numeric_columns_by_dtype():
    table = Table(
        "log.npz",
        ["i", "f", "b", "d"],
        {
            "i": np.array([1, 2], dtype=np.int16),
            "f": np.array([0.5, 1.5], dtype=np.float32),
            "b": np.array([True, False]),
            "d": np.array(["2026-01-01", "2026-01-02"], dtype="datetime64[D]"),
        },
    )
    assert table.numeric("i").dtype == np.float64 and table.numeric("i").tolist() == [1.0, 2.0]
    assert table.numeric("f").dtype == np.float64 and table.numeric("f").tolist() == [0.5, 1.5]
    with pytest.raises(InputError, match="column 'b' holds true/false values"):
        table.numeric("b")
    with pytest.raises(InputError, match="column 'd' holds dates and times"):
        table.numeric("d")
    assert Table("empty", [], {}).n_rows == 0
