"""A log from whatever a user holds (fieldcal.logs.inputs): a file, a mapping, a pyarrow Table
and a pandas DataFrame of the same rows give the same log; malformed tables are refused in one
line."""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.errors import InputError
from fieldcal.logs.inputs import IN_MEMORY, read_log, table_from_frame
from fieldcal.logs.log import Log

COLUMNS = ("pose", "ax", "ay", "az", "mx", "my", "mz")


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    path = tmp_path_factory.mktemp("inputs") / "s.csv"
    fieldcal.simulate("paper", seed=3, n_poses=8).write_csv(path)
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return path, {name: data[:, j] for j, name in enumerate(COLUMNS)}


def _same(a: Log, b: Log) -> None:
    np.testing.assert_array_equal(a.accel, b.accel)
    np.testing.assert_array_equal(a.mag, b.mag)
    assert a.used == b.used
    assert np.array_equal(np.asarray(a.pose, dtype=float), np.asarray(b.pose, dtype=float))


def test_every_form_of_the_same_rows_gives_the_same_log(rows):
    path, columns = rows
    from_file = read_log(path)
    from_mapping = read_log(columns)
    _same(from_file, from_mapping)
    assert from_mapping.path == IN_MEMORY and from_file.accel.shape == (len(columns["ax"]), 3)
    pa = pytest.importorskip("pyarrow", reason="pyarrow (the parquet extra) not installed")
    _same(from_file, read_log(pa.table(columns)))
    assert read_log(from_file) is from_file


def test_a_pandas_frame_with_missing_values(rows):
    pd = pytest.importorskip("pandas", reason="pandas (the pandas extra) not installed")
    _, columns = rows
    frame = pd.DataFrame(columns)
    _same(read_log(columns), read_log(frame))
    frame["ax"] = frame["ax"].astype("Float64")
    frame.loc[3, "ax"] = pd.NA
    table = table_from_frame(frame)
    assert np.isnan(table.columns["ax"][3]) and table.columns["ax"].dtype == float
    log = read_log(frame, drop_nan=True)
    assert log.dropped == 1 and len(log.accel) == len(columns["ax"]) - 1


@pytest.mark.parametrize(
    ("frame", "words"),
    [
        ({}, "the table has no columns"),
        ({"ax": [1.0, 2.0], "ay": [1.0]}, "different lengths (1, 2 rows)"),
        ({"ax": np.ones((2, 2))}, "column 'ax' has shape (2, 2)"),
        (42, "cannot read a log from a int"),
    ],
)
def test_malformed_tables_are_refused(frame, words):
    with pytest.raises(InputError) as info:
        table_from_frame(frame)
    assert words in str(info.value) and "\n" not in str(info.value)


def test_text_columns_stay_text():
    table = table_from_frame(
        {"label": np.array(["up", None, "down"], dtype=object), "ax": [1, 2, 3]}
    )
    assert table.columns["label"].tolist() == ["up", "", "down"]
    assert table.numeric("ax").tolist() == [1.0, 2.0, 3.0]
