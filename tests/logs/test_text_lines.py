"""The lines of a text log (fieldcal.logs.text_lines): which hold data, their fields as the
csv module splits them, and which fields are numbers, against Python's own float() and csv."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldcal.errors import InputError
from fieldcal.logs import text_lines as tl


@settings(max_examples=400, deadline=None)
@given(st.text(alphabet="0123456789.eE+-_ naifINF\uff11\u0661", max_size=8))
def test_a_number_is_what_float_reads_in_ascii_without_underscores(text):
    try:
        float(text)
        reads = True
    except ValueError:
        reads = False
    assert tl._is_number(text) == (reads and text.isascii() and "_" not in text)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.text(alphabet="0123456789.-_ a\uff11", max_size=5), max_size=6))
def test_plain_cells_are_those_of_ascii_without_underscores(cells):
    array = np.array(cells, dtype=str)
    expected = all(c.isascii() and "_" not in c for c in cells)
    assert tl._plain(array) == expected


@settings(max_examples=300, deadline=None)
@given(
    fields=st.lists(st.text(alphabet='ab1 ."', max_size=4), min_size=1, max_size=5),
    delimiter=st.sampled_from([",", ";", "\t"]),
)
def test_fields_are_the_csv_modules(fields, delimiter):
    line = delimiter.join(fields) + "\r\n"
    expected = next(csv.reader([line], delimiter=delimiter), [])
    assert tl._fields(line, delimiter) == expected


@pytest.mark.parametrize(
    ("header", "comma", "delimiter"),
    [("t,ax,ay", False, ","), ("t;ax", False, ";"), ("t\tax", False, "\t"), ("t ax", False, None),
     ("t;a,x", True, ";"), ("t,ax", True, None), ("t;a\tx", False, ";")],
)  # fmt: skip
def test_sniffed_delimiter(header, comma, delimiter):
    assert tl._sniff_delimiter(header, comma) == delimiter


def test_data_lines_numbers_and_commas():
    assert [tl._is_data_line(s) for s in ("1,2\n", "  # c\n", " \t\n", "", "x#\n")] == [
        True, False, False, False, True,
    ]  # fmt: skip
    assert tl._numberish("0,5", ";") and not tl._numberish("0,5", ",")
    assert tl._all_numbers(["1,5", "-2"], ",") and not tl._all_numbers(["1,5"], ".")
    assert tl._short("x" * 100).endswith("...'") and tl._short("ab") == "'ab'"


def test_a_line_the_csv_module_cannot_split_names_its_row():
    long_field = '"' + "x" * (csv.field_size_limit() + 10)
    with pytest.raises(InputError, match=r"log\.csv: cannot split data row 3 into fields"):
        tl._split(["1,2\n", long_field + "\n"], ",", "log.csv", first_row=2)
    assert tl._fields(long_field, ",") is None
    assert tl._split(["a  b\tc\n"], None) == [["a", "b", "c"]]
