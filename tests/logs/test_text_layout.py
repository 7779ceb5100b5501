"""Where a text log's header, delimiter and decimal mark are (fieldcal.logs.text_layout), with
known answers, and the preamble's ``key: value`` lines."""

from __future__ import annotations

import pytest

from fieldcal.errors import InputError
from fieldcal.logs.text_layout import Layout, layout, metadata_key, metadata_lines


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
