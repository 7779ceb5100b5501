"""Delimited text logs (fieldcal.logs.text): random logs written from known numbers read back as
those numbers by both readers (an independent parse: the values the file was written from),
and the parser's edge cases with known answers. The fast path against the careful reader on
random and damaged files is in test_readers.py."""

from __future__ import annotations

import math
import string
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fieldcal.errors import InputError
from fieldcal.logs import text as text_module
from fieldcal.logs.text import (
    parse_numbers,
    read_careful,
    read_text,
)

_SETTINGS = settings(
    max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
_NAME = st.text(alphabet=string.ascii_lowercase + "_", min_size=1, max_size=6).filter(
    lambda s: s not in ("nan", "inf", "infinity")
)


@st.composite
def _known_logs(draw: st.DrawFn):
    """(file content, decimal option, names, expected columns): numbers drawn first, written
    as a logger would (any delimiter, decimal commas, blank cells for missing values, comment
    and blank lines, a ``key: value`` preamble, CRLF, a byte-order mark)."""
    delimiter = draw(st.sampled_from([",", ";", "\t", " "]))
    comma = delimiter in (";", "\t") and draw(st.booleans())
    n_cols = draw(st.integers(2, 5))  # (one column of decimal commas reads as two)
    names = draw(st.lists(_NAME, min_size=n_cols, max_size=n_cols, unique=True))
    n_rows = draw(st.integers(1, 30))
    values = draw(
        st.lists(
            st.lists(
                st.one_of(
                    st.floats(allow_nan=False, allow_infinity=False, width=64),
                    st.integers(-(10**9), 10**9).map(float),
                    st.just(math.nan),
                ),
                min_size=n_cols,
                max_size=n_cols,
            ),
            min_size=n_rows,
            max_size=n_rows,
        )
    )
    # no empty field between blanks: a missing value is written nan there
    blank = "nan" if delimiter == " " else draw(st.sampled_from(["", " ", "nan"]))
    if delimiter == "\t" and blank != "nan":  # a row of empty tab fields is a blank line
        values = [[0.0, *row[1:]] if all(map(math.isnan, row)) else row for row in values]

    def cell(v: float) -> str:
        if math.isnan(v):
            return blank
        text = repr(v)
        return text.replace(".", ",") if comma else text

    lines = [delimiter.join(cell(v) for v in row) for row in values]
    for _ in range(draw(st.integers(0, 3))):
        lines.insert(draw(st.integers(0, len(lines))), draw(st.sampled_from(["", "# note", "  "])))
    preamble = draw(st.lists(st.sampled_from(["# device: IMU-7", "# rate = 100"]), max_size=2))
    eol = draw(st.sampled_from(["\n", "\r\n"]))
    content = eol.join([*preamble, delimiter.join(names), *lines]) + eol
    if draw(st.booleans()):
        content = "\ufeff" + content
    option = draw(st.sampled_from([None, "," if comma else "."]))
    expected = {name: np.array([row[j] for row in values]) for j, name in enumerate(names)}
    return content, option, names, expected


def _write(path: Path, content: str) -> Path:
    path.write_bytes(content.encode("utf-8"))
    return path


@_SETTINGS
@given(log=_known_logs(), arrow=st.booleans())
def test_both_readers_give_back_the_numbers_written(tmp_path, log, arrow):
    content, option, names, expected = log
    path = _write(tmp_path / "log.csv", content)
    at = 0 if arrow else 1 << 62
    with mock.patch.multiple(text_module, ARROW_MIN_BYTES=at, ARROW_MIN_BYTES_LOADED=at):
        for read in (read_text, read_careful):
            table = read(path, decimal=option)
            assert table.names == names
            assert table.n_rows == len(expected[names[0]])
            for name in names:
                got = table.numeric(name)
                # repr round-trips a float64 exactly: equal bit for bit, NaN where blank
                assert np.array_equal(got, expected[name], equal_nan=True), (read, name)
            if "# device: IMU-7" in content:
                assert table.metadata.get("device") == "IMU-7"


def test_a_points_cell_keeps_a_decimal_comma_column_as_text(tmp_path):
    path = _write(tmp_path / "log.csv", "t;ax\n0,5;1\n1,5;2.5\n")
    for read in (read_text, read_careful):
        table = read(path, decimal=",")
        assert table.numeric("t").tolist() == [0.5, 1.5]
        with pytest.raises(InputError, match=r"'2\.5' at data row 2"):
            table.numeric("ax")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("1,2,3\n4,5,6\n", "the first line is numbers, not a header"),
        ("t,ax\n", "has a header but no data rows"),
        ("t,,\n1,2,3\n", "an empty column name appears twice"),
        ("t,ax\n1,2\n1,2,3\n1,2\n", "data row 2 has 3 fields but the header has 2"),
        ('t,ax\n1,"2\n' + "3,4\n" * 300, "a field is longer than 1,000 characters"),
    ],
)
def test_careful_refusals_name_the_fix(tmp_path, content, message):
    path = _write(tmp_path / "log.csv", content)
    for read in (read_text, read_careful):
        with pytest.raises(InputError, match=message):
            read(path)


def test_a_binary_file_is_not_text(tmp_path):
    path = tmp_path / "log.csv"
    path.write_bytes(b"t,ax\n\xff\xfe,1\n")
    with pytest.raises(InputError, match="not a text file"):
        read_text(path)


def test_text_columns_are_stripped_labels(tmp_path):
    path = _write(tmp_path / "log.csv", "pose,ax\n up ,1\ndown,2\n")
    for read in (read_text, read_careful):
        table = read(path)
        assert table.columns["pose"].tolist() == ["up", "down"]
        assert table.numeric("ax").tolist() == [1.0, 2.0]


def test_progress_reports_rows_every_block(tmp_path):
    path = _write(tmp_path / "log.csv", "t,ax\n" + "".join(f"{i},{i}\n" for i in range(50)))
    told: list[str] = []
    with mock.patch.multiple(text_module, PROGRESS_ROWS=20, BLOCK_BYTES=64):
        table = read_text(path, on_progress=told.append)
    assert table.numeric("t").tolist() == list(range(50))
    assert told[-1] == "reading log.csv: 50 rows"
    counts = [int(m.split(": ")[1].split()[0]) for m in told]
    assert counts == sorted(counts) and counts[0] >= 20


def test_parse_numbers_blank_fields_are_nan_and_bad_lines_none():
    got = parse_numbers(["1,,3\n", ",5,\n"], ",", [0, 1, 2])
    assert got is not None
    assert np.array_equal(got, [[1, np.nan, 3], [np.nan, 5, np.nan]], equal_nan=True)
    assert parse_numbers(["1,x,3\n"], ",", [0, 1, 2]) is None
    assert parse_numbers(["1 2 3\n"], None, [0, 2]).tolist() == [[1.0, 3.0]]


@settings(max_examples=100, deadline=None)
@given(
    rows=st.lists(
        st.lists(st.sampled_from(["", "1", "-2.5", "3e3"]), min_size=2, max_size=5),
        min_size=1,
        max_size=6,
    ).filter(lambda rs: len({len(r) for r in rs}) == 1),
    delimiter=st.sampled_from([",", ";", "\t"]),
)
def test_empty_fields_written_nan_as_the_pattern_does(rows, delimiter):
    text = "\n".join(delimiter.join(r) for r in rows)
    filled = text_module._fill_empty(text, delimiter)
    assert filled == text_module._EMPTY[delimiter].sub("nan", text)
    assert filled.split("\n") == [delimiter.join(c or "nan" for c in r) for r in rows]
