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
    Layout,
    Table,
    layout,
    metadata_key,
    metadata_lines,
    parse_numbers,
    read_careful,
    read_text,
    to_float,
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


@pytest.mark.parametrize(
    ("name", "key"),
    [("Serial Number", "serial_number"), (" Sample-Rate.Hz ", "sample_rate_hz"), ("a", "a")],
)
def test_metadata_key(name, key):
    assert metadata_key(name) == key


def test_metadata_lines_first_key_wins_and_rows_are_not_metadata():
    lines = [
        "# Device: IMU-0042\n",
        "Fs,100\n",
        "rate = 200\n",
        "device: other\n",
        "1,2,3\n",  # three fields: a data row, not a pair
        'Owner; "lab 3"\n',
    ]
    assert metadata_lines(lines) == {
        "device": "IMU-0042",
        "fs": "100",
        "rate": "200",
        "owner": "lab 3",
    }


@pytest.mark.parametrize(
    ("lines", "expected"),
    [
        (["t,ax\n", "0,1\n"], Layout("t,ax\n", 0, 1, ",")),
        (["\n", "# c\n", "t;ax\n", "0;1\n"], Layout("t;ax\n", 2, 3, ";")),
        (["t ax\n", "0 1\n"], Layout("t ax\n", 0, 1, None)),
        (
            ["t;ax\n", "0,5;1,25\n"],
            Layout("t;ax\n", 0, 1, ";", ",", ("decimal commas read as points",)),
        ),
        (
            ["Logger v2\n", "t,ax,ay\n", "0,1,2\n", "1,2,3\n"],
            Layout("t,ax,ay\n", 1, 2, ",", ".", ("skipped 1 preamble line(s)",)),
        ),
        (
            ["# t,ax,ay\n", "0,1,2\n", "1,2,3\n"],
            Layout(" t,ax,ay\n", 0, 1, ",", ".", ("header read from the '#' line 1",)),
        ),
    ],
)
def test_layout_known_answers(lines, expected):
    assert layout("log.csv", lines) == expected


def test_layout_refusals():
    with pytest.raises(InputError, match="the file is empty"):
        layout("log.csv", ["\n", "# only a comment\n"])
    with pytest.raises(InputError, match="decimal must be"):
        layout("log.csv", ["t,ax\n"], decimal=";")
    with pytest.raises(InputError, match="decimal=',' needs columns separated by ';'"):
        layout("log.csv", ["t,ax\n", "0,1\n"], decimal=",")


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
