"""pyarrow in the logs room (fieldcal.logs.arrow_parser): a block of data lines parsed as the
numbers written (empty fields NaN), text columns stripped, refusals as None; float columns
read from pyarrow's buffers as pyarrow's own conversion gives them, offsets and nulls too."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.logs.arrow_parser import arrow_parser, float_column, pyarrow_module

pa = pytest.importorskip("pyarrow", reason="pyarrow (the parquet extra) not installed")
pytest.importorskip("pyarrow.csv", reason="pyarrow (the parquet extra) not installed")


def test_a_block_is_parsed_as_the_numbers_written():
    values = np.random.default_rng(1).normal(size=(50, 2))
    labels = [f" pose{i % 3} " for i in range(50)]
    lines = [f"{float(a)!r},{lab},{float(b)!r}" for (a, b), lab in zip(values, labels, strict=True)]
    lines[7] = f"{float(values[7, 0])!r},{labels[7]},"  # an empty field: NaN
    parse = arrow_parser(["ax", "pose", "ay"], [True, False, True], ",", ".")
    assert parse is not None
    numbers, rows, cells = parse(("\n".join(lines) + "\n").encode())
    assert rows == 50
    ax, ay = (np.concatenate(pieces) for pieces in numbers)
    np.testing.assert_array_equal(ax, values[:, 0])  # exact doubles
    expected_ay = values[:, 1].copy()
    expected_ay[7] = np.nan
    np.testing.assert_array_equal(ay, expected_ay)
    assert cells[1].tolist() == [lab.strip() for lab in labels]


def test_decimal_commas_and_refusals():
    parse = arrow_parser(["a", "b"], [True, True], ";", ",")
    numbers, rows, _ = parse(b"0,5;-1,25\n2;3e2\n")
    assert rows == 2 and [np.concatenate(p).tolist() for p in numbers] == [
        [0.5, 2.0],
        [-1.25, 300.0],
    ]
    assert parse(b"1;2;3\n") is None  # a ragged row
    assert parse(b"1;x\n") is None  # a value it does not read: the careful reader explains


def test_float_columns_from_buffers_with_offsets_and_nulls():
    data = [1.5, None, -2.0, 3.25, None, 7.0]
    column = pa.chunked_array([pa.array(data[:2]), pa.array(data[2:])]).slice(1, 4)
    expected = np.array([np.nan if v is None else v for v in data[1:5]])
    np.testing.assert_array_equal(float_column(column), expected)
    assert float_column(pa.chunked_array([], type=pa.float64())).shape == (0,)


def test_modules_load_on_first_use():
    assert pyarrow_module() is pa
    assert pyarrow_module("fieldcal_no_such_module") is None
