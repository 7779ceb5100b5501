"""Reading logs: column spellings, formats, axis maps, NaN handling, streaming apply."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.errors import InputError
from fieldcal.logs import apply_to_file, load_log, parse_axes, read_table, recognise_columns


@pytest.mark.parametrize(
    ("names", "accel", "mag", "gyro"),
    [
        (["ax", "ay", "az", "mx", "my", "mz"], ["ax", "ay", "az"], ["mx", "my", "mz"], None),
        (  # imucal
            ["n_samples", "gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y", "acc_z"],
            ["acc_x", "acc_y", "acc_z"],
            None,
            ["gyr_x", "gyr_y", "gyr_z"],
        ),
        (  # sap6
            ["device", "shot", "group", "mag_x", "mag_y", "mag_z", "grav_x", "grav_y", "grav_z"],
            ["grav_x", "grav_y", "grav_z"],
            ["mag_x", "mag_y", "mag_z"],
            None,
        ),
        (  # icm20948-deadtomgc
            [
                "sample",
                "ax_g",
                "ay_g",
                "az_g",
                "gx_dps",
                "gy_dps",
                "gz_dps",
                "mx_rawdiv10",
                "my_rawdiv10",
                "mz_rawdiv10",
            ],
            ["ax_g", "ay_g", "az_g"],
            ["mx_rawdiv10", "my_rawdiv10", "mz_rawdiv10"],
            ["gx_dps", "gy_dps", "gz_dps"],
        ),
        (  # ROS bag export and unit suffixes
            [
                "%time",
                "field.linear_acceleration.x",
                "field.linear_acceleration.y",
                "field.linear_acceleration.z",
                "Accel X (g)",
                "AccelY",
                "accel_z",
            ],
            [
                "field.linear_acceleration.x",
                "field.linear_acceleration.y",
                "field.linear_acceleration.z",
            ],
            None,
            None,
        ),
        (
            ["AccX", "AccY", "AccZ", "MagX", "MagY", "MagZ"],
            ["AccX", "AccY", "AccZ"],
            ["MagX", "MagY", "MagZ"],
            None,
        ),
    ],
)
def test_column_spellings(names, accel, mag, gyro):
    found = recognise_columns(names)
    assert found.get("accel") == accel
    assert found.get("mag") == mag
    assert found.get("gyro") == gyro


def test_time_and_pose_columns():
    found = recognise_columns(["timestamp_ms", "pose", "ax", "ay", "az"])
    assert found["time"] == ["timestamp_ms"] and found["pose"] == ["pose"]


@pytest.mark.parametrize(
    ("spec", "raw", "mapped"),
    [
        ("+x+y+z", (1, 2, 3), (1, 2, 3)),
        ("+y+x-z", (1, 2, 3), (2, 1, -3)),
        ("x-y-z", (1, 2, 3), (1, -2, -3)),
        ("-Y-X+Z", (1, 2, 3), (-2, -1, 3)),
    ],
)
def test_parse_axes(spec, raw, mapped):
    assert np.array_equal(parse_axes(spec) @ np.array(raw, float), mapped)


@pytest.mark.parametrize("spec", ["+x+x+z", "xy", "+a+b+c", "+x+y+z+x"])
def test_parse_axes_rejects(spec):
    with pytest.raises(InputError, match="axis map"):
        parse_axes(spec)


def _write(path, text):
    path.write_text(text)
    return path


def test_csv_delimiters_comments_and_time_units(tmp_path):
    path = _write(
        tmp_path / "log.csv",
        "# banner from the logger\nmillis;ax;ay;az\n0;1;0;0\n10;0;1;0\n20;0;0;1\n",
    )
    log = load_log(path)
    assert log.accel.shape == (3, 3) and log.mag is None
    assert np.allclose(log.time, [0, 0.01, 0.02])  # milliseconds recognised


def test_npz_and_parquet_match_csv(tmp_path):
    rng = np.random.default_rng(0)
    a, m = rng.normal(size=(20, 3)), rng.normal(size=(20, 3))
    np.savez(tmp_path / "log.npz", accel=a, mag=m, t=np.arange(20) / 50)
    log = load_log(tmp_path / "log.npz")
    assert np.array_equal(log.accel, a) and np.array_equal(log.mag, m)
    assert log.used["accel"] == ["accel_x", "accel_y", "accel_z"]
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    table = pa.table({"acc_x": a[:, 0], "acc_y": a[:, 1], "acc_z": a[:, 2], "label": ["p"] * 20})
    pq.write_table(table, tmp_path / "log.parquet")
    log = load_log(tmp_path / "log.parquet")
    assert np.array_equal(log.accel, a) and log.used["pose"] == ["label"]


def test_nan_rows_refused_or_dropped(tmp_path):
    path = _write(tmp_path / "log.csv", "ax,ay,az\n1,2,3\nnan,2,3\n1,,3\n4,5,6\n")
    with pytest.raises(InputError, match=r"2 row\(s\).*--drop-nan"):
        load_log(path)
    log = load_log(path, drop_nan=True)
    assert log.dropped == 2 and np.array_equal(log.index, [0, 3])


def test_non_numeric_names_the_value(tmp_path):
    path = _write(tmp_path / "log.csv", "ax,ay,az\n1,2,3\n1,oops,3\n")
    with pytest.raises(InputError, match=r"'ay'.*'oops'.*row 2"):
        load_log(path)


def test_missing_columns_lists_found(tmp_path):
    path = _write(tmp_path / "log.csv", "foo,bar\n1,2\n")
    with pytest.raises(InputError, match="foo, bar"):
        load_log(path)
    with pytest.raises(InputError, match="no column 'qx'"):
        load_log(_write(tmp_path / "b.csv", "ax,ay,az\n1,2,3\n"), accel_cols="qx,ay,az")


def test_headerless_file_refused(tmp_path):
    with pytest.raises(InputError, match="header"):
        read_table(_write(tmp_path / "log.txt", "1 2 3\n4 5 6\n"))


class _Identity:
    """A calibration stand-in: correct_* doubles the reading."""

    accel = mag = object()

    @staticmethod
    def correct_accel(raw):
        return 2 * np.asarray(raw)

    correct_mag = correct_accel


def test_apply_streams_in_chunks(tmp_path):
    rng = np.random.default_rng(1)
    data = rng.normal(size=(1001, 6))
    src = tmp_path / "log.csv"
    np.savetxt(
        src,
        np.column_stack([np.arange(1001), data]),
        delimiter=",",
        comments="",
        header="t,ax,ay,az,mx,my,mz",
        fmt="%.17g",
    )
    used = apply_to_file(_Identity(), src, tmp_path / "out.csv", chunk_rows=100)
    assert used == {"accel": ["ax", "ay", "az"], "mag": ["mx", "my", "mz"]}
    out = np.genfromtxt(tmp_path / "out.csv", delimiter=",", names=True)
    assert len(out) == 1001
    assert np.allclose(out["ax_cal"], 2 * data[:, 0], rtol=1e-8)
    assert np.allclose(out["mz_cal"], 2 * data[:, 5], rtol=1e-8)
    assert np.array_equal(out["t"], np.arange(1001))
