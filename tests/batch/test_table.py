"""The batch's summary table (fieldcal.batch.table): a row read back from the CSV by the csv
module and from Parquet by pyarrow as the calibration's numbers, fixed columns whatever the log
held, failures counted."""

from __future__ import annotations

import csv
import dataclasses
import io
import math

import numpy as np
import pytest
from _known import ACCEL_GAIN, MAG_BIAS, known_calibration

from fieldcal.batch import table
from fieldcal.calibration import Reason, Verdict


def _row():
    cal = dataclasses.replace(
        known_calibration(),
        verdict=Verdict("warn", (Reason("accuracy", "warn", "tilt 1.2°, over 1°"),)),
    )
    return table.row_for(cal, device="imu-7", log="a.csv", samples=1200, seconds=0.5, version="x")


def test_a_row_holds_the_calibrations_numbers():
    row = _row()
    assert set(row) == set(table.COLUMNS)
    assert row["accel.gain[0,1]"] == ACCEL_GAIN[0, 1] and row["mag.bias[2]"] == MAG_BIAS[2]
    assert math.isnan(row["accel.gain[0,1]_std"])  # no covariance: no error bar
    assert math.isnan(row["gyro.bias[0]"])  # no gyroscope: absent, the column still there
    assert (row["verdict"], row["reason_codes"], row["n_poses"]) == ("warn", "accuracy", 3)
    assert row["dip_deg"] == pytest.approx(60.0) and row["field_strength"] == pytest.approx(48.5)
    assert not table.failed(row)


def test_the_csv_reads_back_the_exact_doubles_and_empty_cells():
    rows = [_row(), table.error_row("imu-8", "b.csv", "bad\n column", seconds=0.1, version="x")]
    read = list(csv.DictReader(io.StringIO(table.csv_text(rows))))
    assert list(read[0]) == list(table.COLUMNS)
    assert float(read[0]["accel.gain[0,0]"]) == ACCEL_GAIN[0, 0]
    assert read[0]["gyro.bias[0]"] == "" and read[1]["accel.gain[0,0]"] == ""
    assert read[1]["error"] == "bad column" and read[1]["verdict"] == "fail"
    assert table.failed(rows[1]) and table.failed({"verdict": "pass", "export_error": "x"})


def test_parquet_types_and_nulls(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow (the parquet extra) not installed")
    rows = [_row(), table.error_row("imu-8", "b.csv", "bad", seconds=0.1, version="x")]
    written = table.write_summary(rows, tmp_path)
    assert sorted(p.name for p in written) == ["summary.csv", "summary.parquet"]
    back = pq.read_table(tmp_path / "summary.parquet").to_pydict()
    assert back["mag.bias[0]"] == [MAG_BIAS[0], None]  # absent numbers are null
    assert back["n_poses"] == [3, None] and back["device"] == ["imu-7", "imu-8"]
    assert list(back) == list(table.COLUMNS)
    for name, kind in table.COLUMN_TYPES.items():
        values = [v for v in back[name] if v is not None]
        assert all(isinstance(v, kind) for v in values), name


def test_pandas_frame_types():
    pytest.importorskip("pandas", reason="pandas (the pandas extra) not installed")
    frame = table.to_pandas([_row()])
    assert str(frame["n_poses"].dtype) == "Int64" and frame["mag.bias[1]"].iloc[0] == MAG_BIAS[1]
    assert np.isnan(frame["gyro.bias[0]"].iloc[0])
