"""apply_to_file's dispatch: the files it refuses in one line before reading, and the format
chosen by the output's suffix (an NPZ's sensor array keeps its shape)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from _logs import _Double

from fieldcal.errors import InputError
from fieldcal.logs.apply import apply_to_file, output_format


def _csv(path):
    path.write_text("ax,ay,az\n1,2,3\n4,5,6\n")
    return path


def test_the_suffix_names_the_format():
    assert [output_format(p) for p in ("a.PARQUET", "b.pq", "c.npz", "d.tsv", "e")] == [
        "parquet",
        "parquet",
        "npz",
        "text",
        "text",
    ]


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda p: p / "missing.csv", "no such file"),
        (lambda p: p, "is a folder"),
        (lambda p: _binary(p / "bin.csv"), "not a text file"),
    ],
)
def test_unreadable_sources_are_refused_in_one_line(tmp_path, make, match):
    with pytest.raises(InputError, match=match) as refused:
        apply_to_file(_Double(), make(tmp_path), tmp_path / "out.csv")
    assert "\n" not in str(refused.value)
    assert not (tmp_path / "out.csv").exists()


def _binary(path):
    path.write_bytes(b"ax,ay,az\n\xff\xfe\x00\x81\n")
    return path


def test_the_log_itself_and_a_wrong_decimal_mark_are_refused(tmp_path):
    src = _csv(tmp_path / "log.csv")
    with pytest.raises(InputError, match="is the input log"):
        apply_to_file(_Double(), src, src)
    with pytest.raises(InputError, match="decimal must be"):
        apply_to_file(_Double(), src, tmp_path / "out.csv", decimal=";")
    assert src.read_text() == "ax,ay,az\n1,2,3\n4,5,6\n"


def test_an_npz_sensor_array_gets_a_calibrated_array_of_its_shape(tmp_path):
    accel = np.arange(12.0).reshape(4, 3)
    np.savez(tmp_path / "log.npz", accel=accel, t=np.arange(4.0))
    used = apply_to_file(
        _Double(), tmp_path / "log.npz", tmp_path / "out.npz", accel_cols="accel_x,accel_y,accel_z"
    )
    assert used == {"accel": ["accel_x", "accel_y", "accel_z"]}
    with np.load(tmp_path / "out.npz") as out:
        np.testing.assert_array_equal(out["accel_cal"], 2 * accel)
        np.testing.assert_array_equal(out["accel"], accel)


def test_a_flight_logs_sensor_instances_reach_its_reader(tmp_path):
    """--mag/--imu as calibrate reads them: an instance the log lacks is refused by name."""
    pytest.importorskip("pyulog", reason="the [ulog] extra (pyulog) is not installed")
    log = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "px4-ulog"
    log = log / "sample_log_small.ulg"
    if not log.is_file():
        pytest.skip(f"{log} is absent (../shared/data beside the repository)")
    with pytest.raises(InputError, match="no mag instance 5"):
        apply_to_file(_Double(), log, tmp_path / "out.csv", mag_instance=5)
    apply_to_file(_Double(), log, tmp_path / "out.csv", mag_instance=0, accel_cols="ax,ay,az")
    assert "ax_cal" in (tmp_path / "out.csv").read_text().splitlines()[0]
