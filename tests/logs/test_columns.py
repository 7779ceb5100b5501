"""Reading logs: column spellings, formats, axis maps, NaN handling, streaming apply."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from _logs import _Double

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
    pa = pytest.importorskip("pyarrow", reason="pyarrow (the parquet extra) not installed")
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


# ----------------------------------------------------------------------------- bad input
def _lines(exc_info):
    text = str(exc_info.value)
    assert "\n" not in text and len(text) < 400, text
    return text


def test_special_files_are_refused_before_opening(tmp_path):
    """A FIFO would block the reader forever and a device never ends: both refused by stat."""
    fifo = tmp_path / "log.csv"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="is a pipe") as info:
        read_table(fifo)  # returns at once: nothing opens the pipe
    _lines(info)
    with pytest.raises(InputError, match="is a folder"):
        read_table(tmp_path)
    if Path("/dev/zero").exists():
        with pytest.raises(InputError, match="is a device or socket, not a file"):
            load_log("/dev/zero")
    (tmp_path / "link.csv").symlink_to(tmp_path / "gone.csv")
    with pytest.raises(InputError, match="no such file"):
        read_table(tmp_path / "link.csv")


def _npz_bytes(**arrays):
    import io

    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "not a readable .npz archive"),
        (b"PK\x03\x04garbage", "not a readable .npz archive"),
        (_npz_bytes(accel=np.ones((5, 3)))[:-30], "not a readable .npz archive"),
        (b"ax,ay,az\n1,2,3\n", "not a readable .npz archive"),
    ],
)
def test_broken_npz_is_one_line(tmp_path, content, message):
    path = tmp_path / "log.npz"
    path.write_bytes(content)
    with pytest.raises(InputError, match=message) as info:
        read_table(path)
    _lines(info)


def test_npz_contents_that_are_not_readings(tmp_path):
    np.save(tmp_path / "bare.npy", np.ones((5, 3)))
    (tmp_path / "bare.npz").write_bytes((tmp_path / "bare.npy").read_bytes())
    with pytest.raises(InputError, match=r"single \.npy array"):
        read_table(tmp_path / "bare.npz")
    np.savez(tmp_path / "obj.npz", accel=np.array([[1, 2, 3]] * 4, dtype=object))
    with pytest.raises(InputError, match="allow_pickle"):
        read_table(tmp_path / "obj.npz")
    for dtype, what in [(complex, "complex numbers"), (bool, "true/false values")]:
        np.savez(tmp_path / "c.npz", accel=np.ones((5, 3), dtype=dtype))
        with pytest.raises(InputError, match=f"'accel_x' holds {what}"):
            load_log(tmp_path / "c.npz")
    np.savez(tmp_path / "h.npz", accel=np.ones((5, 3), dtype=np.float16), mag=np.ones((5, 3)))
    assert load_log(tmp_path / "h.npz").accel.dtype == np.float64
    np.savez(tmp_path / "len.npz", accel=np.ones((5, 3)), t=np.arange(4.0))
    with pytest.raises(InputError, match=r"different lengths \(t 4, accel_x 5 rows\)"):
        read_table(tmp_path / "len.npz")
    np.savez(tmp_path / "none.npz", accel=np.ones((3, 5, 2)))
    with pytest.raises(InputError, match=r"found accel \[3, 5, 2\]"):
        read_table(tmp_path / "none.npz")


def test_csv_damage_is_one_line_naming_the_row(tmp_path):
    rows = "".join(f"{i},{i},{i}\n" for i in range(5))
    huge = _write(tmp_path / "a.csv", f"ax,ay,az\n{rows}1,{'x' * 200_000},3\n")
    with pytest.raises(InputError, match=r"cannot split data row 6 into fields .*limit"):
        read_table(huge)
    long = _write(tmp_path / "a.csv", f"ax,ay,az\n{rows}1,{'x' * 5000},3\n{rows * 30_000}")
    with pytest.raises(InputError, match=r"data row 6 has a field of 5,000 characters"):
        read_table(long)  # before numpy makes every cell 5,000 characters wide
    quote = _write(tmp_path / "b.csv", f'ax,ay,az\n{rows}"1,2,3\n{rows * 30_000}')
    with pytest.raises(InputError, match="unmatched quote") as info:
        read_table(quote)
    _lines(info)
    with pytest.raises(InputError, match=r"column name 'ay' appears twice \(columns 2 and 3\)"):
        read_table(_write(tmp_path / "c.csv", f"ax,ay,ay\n{rows}"))
    # a preamble above a header is skipped (tests/test_readers.py); with no header below it
    # the first line is named
    preamble = _write(tmp_path / "d.csv", f"Logger v2\n{rows}")
    with pytest.raises(InputError, match=r"first line 'Logger v2' is not a header .*','"):
        read_table(preamble)
    preamble = _write(tmp_path / "d.csv", f"device,imu-7\n{rows}")
    with pytest.raises(InputError, match=r"header line 'device,imu-7' has 2 field.*above the"):
        read_table(preamble)
    (tmp_path / "e.csv").write_bytes(b"ax,ay,az\n1,2,3\n\xff\xfe,1,2\n")
    with pytest.raises(InputError, match="not a text file"):
        read_table(tmp_path / "e.csv")


def test_out_of_range_values_are_named_with_row_and_column(tmp_path):
    path = _write(tmp_path / "a.csv", "ax,ay,az,mx,my,mz\n1,2,3,4,5,6\n1,2,3,4,1e300,6\n")
    with pytest.raises(InputError, match=r"column 'my' has the value 1e\+300 at data row 2") as i:
        load_log(path)
    assert "smaller unit" in _lines(i)
    path = _write(tmp_path / "b.csv", "ax,ay,az,mx,my,mz\n1,2,3,4,5,6\n1,2,inf,4,5,6\n")
    with pytest.raises(InputError, match=r"first at data row 2, column 'az'"):
        load_log(path)
    path = _write(tmp_path / "c.csv", "t,ax,ay,az\n-1e308,1,2,3\n1e308,1,2,3\n")
    with pytest.raises(InputError, match="time column 't' spans more than floating point"):
        load_log(path)


def test_the_log_limit_is_the_calibration_limit():
    from fieldcal.logs.log import LARGEST
    from fieldcal.stats.pose_stats import LARGEST as STATS_LARGEST

    assert LARGEST == STATS_LARGEST  # logs cannot import stats (same rank): one value, checked


def test_one_column_is_not_two_things(tmp_path):
    path = _write(tmp_path / "a.csv", "t,ax,ay,az,mx,my,mz\n0,1,2,3,4,5,6\n")
    with pytest.raises(InputError, match="'mx' is used for the accelerometer and for the magn"):
        load_log(path, accel_cols="mx,my,mz")
    with pytest.raises(InputError, match="'t' is used for the time and for the pose labels"):
        load_log(path, pose_col="t")
    with pytest.raises(InputError, match="repeat a column"):
        load_log(path, accel_cols="ax,ax,ay")
    with pytest.raises(InputError, match="three column names"):
        load_log(path, accel_cols=["ax", "ay", 3])
    with pytest.raises(InputError, match="drop_nan must be True or False"):
        load_log(path, drop_nan="yes")


def _continuous_csv(path, factor=1.0, rate=100.0, seed=3):
    from fieldcal.simulation.continuous import simulate_continuous

    sim = simulate_continuous("paper", seed=seed, rate=rate)
    columns = {k: (v if k == "t" else v * factor) for k, v in sim.columns.items()}
    np.savetxt(
        path,
        np.column_stack(list(columns.values())),
        delimiter=",",
        header=",".join(columns),
        comments="",
        fmt="%.17g",
    )
    return path


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"window": float("inf")}, "--window must be a positive number of seconds"),
        ({"window": 1e300}, r"--window 1e\+300 .* is longer than the log"),
        ({"min_still": float("nan")}, "--min-still must be a positive number"),
        ({"trim": float("inf")}, "--still-trim must be a non-negative number"),
        ({"trim": 1e300}, "--still-trim .* is longer than the log"),
        ({"threshold": float("nan")}, "--still-threshold must be a positive"),
        ({"threshold": 0.0}, "--still-threshold must be a positive"),
        ({"rate": "100"}, "--rate must be a positive number"),
        ({"factor": 1e300}, "out of the range floating point can hold"),
    ],
)
def test_detection_options_are_checked_as_values(tmp_path, options, message):
    import warnings

    from fieldcal.logs import poses_from_log

    log = load_log(_continuous_csv(tmp_path / "log.csv"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy warning on the way
        with pytest.raises(InputError, match=message) as info:
            poses_from_log(log, **options)
    _lines(info)


@pytest.mark.parametrize("factor", [1e-30, 1e30])
def test_the_log_path_is_scale_invariant(tmp_path, factor):
    """Data in tiny or huge units: the same poses, gains scaled, the same verdict but for the
    reason that no physical unit explains the scale."""
    import fieldcal
    from fieldcal.logs import poses_from_log
    from fieldcal.pipeline import calibrate_log

    results = []
    for f in (1.0, factor):
        log = load_log(_continuous_csv(tmp_path / f"log{f:g}.csv", f))
        poses = poses_from_log(log)
        results.append((poses, calibrate_log(log, poses=poses)))
    (p0, c0), (p1, c1) = results
    assert [e["start"] for e in p1.entries] == [e["start"] for e in p0.entries]
    assert [e["stop"] for e in p1.entries] == [e["stop"] for e in p0.entries]
    assert p1.detection.threshold == pytest.approx(p0.detection.threshold * factor**2, rel=1e-9)
    np.testing.assert_allclose(c1.accel.gain / factor, c0.accel.gain, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(c1.mag.bias / factor, c0.mag.bias, rtol=1e-9, atol=1e-12)
    assert c1.dip_deg == pytest.approx(c0.dip_deg, abs=1e-9)
    # the same verdict, and a warning that no unit explains such a scale (issue 35, S3); a
    # gyroscope in such units is no physical one either
    gyro = ("gyro_gain", "gyro_misalignment")
    scale = [r for r in c1.verdict.reasons if r.code == "unexplained_scale"]
    assert len(scale) >= 2 and c1.verdict.level == "warn"  # accel, mag (and gyro)
    kept = [r for r in c1.verdict.reasons if r not in scale and r.code not in gyro]
    assert kept == [r for r in c0.verdict.reasons if r.code not in gyro]
    assert "gyro_gain" not in c0.verdict.codes
    assert isinstance(c1, fieldcal.Calibration)


def test_a_pose_column_with_a_label_per_row(tmp_path):
    """Samples of still poses each labelled apart: an error in well under a second; shots
    (one row per pose, each in a new orientation) stay poses."""

    import fieldcal
    from fieldcal.logs import poses_from_log

    s = fieldcal.simulate("paper", seed=1)
    a, m = np.concatenate(s.accel), np.concatenate(s.mag)
    rows = np.column_stack([np.arange(len(a)), a, m])
    path = tmp_path / "rows.csv"
    np.savetxt(path, rows, delimiter=",", header="n,ax,ay,az,mx,my,mz", comments="")
    with pytest.raises(InputError, match="gives every row its own label") as info:
        poses_from_log(load_log(path, pose_col="n"))
    assert f"({len(a)} rows)" in _lines(info)
    shots = fieldcal.simulate("paper", seed=1, n_poses=10_000, samples=(1, 1))
    a, m = np.concatenate(shots.accel), np.concatenate(shots.mag)
    path = tmp_path / "shots.csv"
    np.savetxt(
        path, np.column_stack([np.arange(len(a)), a, m]), delimiter=",",
        header="shot,ax,ay,az,mx,my,mz", comments="",
    )  # fmt: skip
    log = load_log(path, pose_col="shot")
    poses = poses_from_log(log)  # linear in the labels: benchmarks/scaling.py times it
    assert poses.n == 10_000


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
    used = apply_to_file(_Double(), src, tmp_path / "out.csv", chunk_rows=100)
    assert used == {"accel": ["ax", "ay", "az"], "mag": ["mx", "my", "mz"]}
    out = np.genfromtxt(tmp_path / "out.csv", delimiter=",", names=True)
    assert len(out) == 1001
    assert np.allclose(out["ax_cal"], 2 * data[:, 0], rtol=1e-8)
    assert np.allclose(out["mz_cal"], 2 * data[:, 5], rtol=1e-8)
    assert np.array_equal(out["t"], np.arange(1001))


# ----------------------------------------------------------------------------- apply keeps all
def _no_temporaries(folder):
    return [p.name for p in folder.iterdir() if p.name.endswith(".part")] == []


def test_apply_keeps_every_line_byte_for_byte(tmp_path):
    """Comment and blank lines in place, CRLF endings, a byte-order mark, a quoted header name
    holding the delimiter, the original text of every field; calibrated values in full
    precision, their names quoted as the csv module quotes."""
    rng = np.random.default_rng(2)
    raw = rng.normal(size=(40, 6))
    lines = ["\ufeff# logger banner\r\n", "\r\n", 't;"note; x";ax;ay;"a;z";mx;my;mz\r\n']
    for i, row in enumerate(raw):
        if i == 5:
            lines += ["# a comment between rows\r\n", "\r\n"]
        fields = [f"{1.7e9 + 0.01 * i:.2f}", f'"hi; {i}"', *[f"{v:.6g}" for v in row]]
        lines.append(";".join(fields) + "\r\n")
    src = tmp_path / "log.csv"
    src.write_bytes("".join(lines).encode("utf-8"))
    used = apply_to_file(_Double(), src, tmp_path / "out.csv", accel_cols="ax,ay,a;z", chunk_rows=7)
    assert used == {"accel": ["ax", "ay", "a;z"], "mag": ["mx", "my", "mz"]}
    out = (tmp_path / "out.csv").read_bytes().decode("utf-8").splitlines(keepends=True)
    assert len(out) == len(lines)
    for before, after in zip(lines, out, strict=True):
        if before.strip("\ufeff\r\n").startswith("#") or not before.strip():
            assert after == before  # comments and blank lines as they were
        else:
            assert after.startswith(before[:-2] + ";") and after.endswith("\r\n")
    import csv

    rows = list(
        csv.reader(
            [line.lstrip("\ufeff") for line in out[2:] if line[0] not in "#\r"], delimiter=";"
        )
    )
    assert rows[0][-6:] == ["ax_cal", "ay_cal", "a;z_cal", "mx_cal", "my_cal", "mz_cal"]
    assert all(len(r) == len(rows[0]) == 14 for r in rows)  # aligned under the header
    data = np.array([[float(v) for v in r[2:8]] for r in rows[1:]])
    calibrated = np.array([[float(v) for v in r[8:]] for r in rows[1:]])
    assert np.array_equal(calibrated, 2 * data)  # full precision: equal, not close


def test_apply_whitespace_separated_and_no_final_newline(tmp_path):
    src = _write(tmp_path / "log.txt", "# banner\nax  ay az\n1 2   3\n\n4 5 6")
    apply_to_file(_Double(), src, tmp_path / "out.txt", mag_cols=None)
    assert (tmp_path / "out.txt").read_text() == (
        "# banner\nax  ay az ax_cal ay_cal az_cal\n1 2   3 2.0 4.0 6.0\n\n4 5 6 8.0 10.0 12.0"
    )


def test_apply_npz_keeps_every_array_as_it_was(tmp_path):
    """dtype and shape of every array, scalars and a key ``file`` included; the time column
    t = 1.7e9 + 0.01 i keeps all its distinct values; an (n, 3) sensor array gets an (n, 3)
    calibrated one."""
    import zipfile

    rng = np.random.default_rng(3)
    n = 500
    arrays = {
        "accel": rng.normal(size=(n, 3)).astype(np.float32),
        "mag": rng.normal(size=(n, 3)),
        "t": 1.7e9 + 0.01 * np.arange(n),
        "file": np.arange(n, dtype=np.int16),
        "rate": np.array(100.0),
    }
    src = tmp_path / "log.npz"
    with zipfile.ZipFile(src, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for key, array in arrays.items():
            with archive.open(f"{key}.npy", "w") as member:
                np.lib.format.write_array(member, array)
    apply_to_file(_Double(), src, tmp_path / "out.npz")
    with np.load(tmp_path / "out.npz") as out:
        for key, array in arrays.items():
            assert out[key].dtype == array.dtype and np.array_equal(out[key], array)
        assert out["accel_cal"].shape == (n, 3) and out["accel_cal"].dtype == np.float64
        assert np.array_equal(out["accel_cal"], 2 * arrays["accel"].astype(np.float64))
        assert len(np.unique(out["t"])) == n
    with zipfile.ZipFile(tmp_path / "out.npz") as archive:  # compressed in, compressed out
        assert {i.compress_type for i in archive.infolist()} == {zipfile.ZIP_DEFLATED}
    # as CSV: the scalar cannot be a column, so it is refused rather than dropped
    with pytest.raises(InputError, match=r"'rate'.*write the output as \.npz"):
        apply_to_file(_Double(), src, tmp_path / "out.csv")
    columns = {k: v for k, v in arrays.items() if k not in ("rate", "file")}
    np.savez(tmp_path / "cols.npz", counter=arrays["file"], **columns)
    apply_to_file(_Double(), tmp_path / "cols.npz", tmp_path / "out.csv")
    text = np.genfromtxt(tmp_path / "out.csv", delimiter=",", names=True)
    assert np.array_equal(text["t"], arrays["t"]) and len(np.unique(text["t"])) == n
    assert np.array_equal(text["counter"], arrays["file"])
    header, first = (tmp_path / "out.csv").read_text().splitlines()[:2]
    # float32 written as its own shortest text, which reads back as the same float32
    x = first.split(",")[header.split(",").index("accel_x")]
    assert np.float32(x) == arrays["accel"][0, 0] and len(x) <= 12


def test_apply_parquet_keeps_its_types(tmp_path):
    pa = pytest.importorskip("pyarrow", reason="pyarrow (the parquet extra) not installed")
    import pyarrow.parquet as pq

    rng = np.random.default_rng(4)
    n = 50
    table = pa.table(
        {
            "t": 1.7e9 + 0.01 * np.arange(n),
            "count": pa.array(np.arange(n), pa.int32()),
            "ax": rng.normal(size=n).astype(np.float32),
            "ay": rng.normal(size=n),
            "az": rng.normal(size=n),
            "label": pa.array(["p"] * (n - 1) + [None]),
            "when": pa.array(np.arange(n).astype("datetime64[ms]")),
        }
    )
    pq.write_table(table, tmp_path / "log.parquet")
    apply_to_file(_Double(), tmp_path / "log.parquet", tmp_path / "out.parquet")
    out = pq.read_table(tmp_path / "out.parquet")
    assert out.select(table.schema.names).equals(table)  # types and values as they were
    assert out.schema.field("ax_cal").type == pa.float64()
    assert np.array_equal(out.column("ax_cal").to_numpy(), 2 * table.column("ax").to_numpy())
    # and into the other formats
    apply_to_file(_Double(), tmp_path / "log.parquet", tmp_path / "out.npz")
    with np.load(tmp_path / "out.npz") as data:
        assert data["count"].dtype == np.int32 and data["ax"].dtype == np.float32
        assert list(data["label"][-2:]) == ["p", ""]
    apply_to_file(_Double(), tmp_path / "out.npz", tmp_path / "again.parquet", accel_cols="t,t,t")
    # CSV in, Parquet out: numbers as doubles, the calibrated columns appended
    np.savetxt(
        tmp_path / "log.csv",
        np.column_stack([np.arange(n), rng.normal(size=(n, 3))]),
        delimiter=",",
        header="t,ax,ay,az",
        comments="",
        fmt="%.17g",
    )
    apply_to_file(_Double(), tmp_path / "log.csv", tmp_path / "csv.parquet")
    assert pq.read_table(tmp_path / "csv.parquet").schema.names[-1] == "az_cal"


def test_apply_names_pyarrow_when_missing(tmp_path, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "pyarrow" else real(name, *a)
    )
    src = _write(tmp_path / "log.csv", "ax,ay,az\n1,2,3\n")
    with pytest.raises(InputError, match=r"pip install 'fieldcal\[parquet\]'"):
        apply_to_file(_Double(), src, tmp_path / "out.parquet")
    assert not (tmp_path / "out.parquet").exists()


def test_apply_refuses_its_input_and_a_calibrated_log(tmp_path):
    src = _write(tmp_path / "log.csv", "ax,ay,az\n1,2,3\n")
    (tmp_path / "hard.csv").hardlink_to(src)
    (tmp_path / "soft.csv").symlink_to(src)
    for dst in ("log.csv", "hard.csv", "soft.csv"):
        with pytest.raises(InputError, match="is the input log"):
            apply_to_file(_Double(), src, tmp_path / dst)
    assert src.read_text() == "ax,ay,az\n1,2,3\n"
    calibrated = _write(tmp_path / "cal.csv", "ax,ay,az,ax_cal\n1,2,3,4\n")
    with pytest.raises(InputError, match="already has the column 'ax_cal'"):
        apply_to_file(_Double(), calibrated, tmp_path / "out.csv")


def test_apply_interrupted_or_stopped_leaves_the_old_output(tmp_path):
    rng = np.random.default_rng(5)
    src = tmp_path / "log.csv"
    rows = [",".join(f"{v:.17g}" for v in row) for row in rng.normal(size=(1000, 3))]
    rows[900] = "1,oops,3"
    src.write_text("ax,ay,az\n" + "\n".join(rows) + "\n")
    dst = _write(tmp_path / "out.csv", "the previous output\n")
    with pytest.raises(InputError, match=r"'oops' at data row 901"):
        apply_to_file(_Double(), src, dst, chunk_rows=100)
    assert dst.read_text() == "the previous output\n" and _no_temporaries(tmp_path)

    class Interrupted(_Double):
        calls = 0

        @classmethod
        def correct_accel(cls, raw, temperature=None):
            cls.calls += 1
            if cls.calls == 3:
                raise KeyboardInterrupt
            return 2 * np.asarray(raw)

    with pytest.raises(KeyboardInterrupt):
        apply_to_file(Interrupted(), src, dst, chunk_rows=100)
    assert dst.read_text() == "the previous output\n" and _no_temporaries(tmp_path)


# ----------------------------------------------------------------------------- _files
def test_replacing_leaves_the_old_file_or_the_new_one(tmp_path):
    from fieldcal import _files

    target = _write(tmp_path / "f.txt", "old\n")
    target.chmod(0o640)
    with pytest.raises(KeyboardInterrupt), _files.replacing(target) as temp:
        temp.write_text("half")
        raise KeyboardInterrupt
    assert target.read_text() == "old\n" and _no_temporaries(tmp_path)
    with _files.record() as done:
        _files.write_text(target, "new\n")
    assert target.read_text() == "new\n" and done == [target]
    assert target.stat().st_mode & 0o777 == 0o640  # the permissions of the file replaced
    # a symbolic link stays a link; the file it points to is replaced
    link = tmp_path / "link.txt"
    link.symlink_to(target)
    _files.write_text(link, "through the link\n")
    assert link.is_symlink() and target.read_text() == "through the link\n"
    assert _no_temporaries(tmp_path)


def test_check_outputs(tmp_path):
    from fieldcal._files import check_outputs

    log = _write(tmp_path / "log.csv", "ax\n1\n")
    (tmp_path / "hard.csv").hardlink_to(log)
    (tmp_path / "soft.csv").symlink_to(log)
    inputs = {"log": log}
    for name in ("log.csv", "hard.csv", "soft.csv"):
        with pytest.raises(InputError, match="input log"):
            check_outputs([tmp_path / name], inputs, force=True)
    with pytest.raises(InputError, match="exists; pass --force to replace it"):
        check_outputs([log], {}, force=False)
    check_outputs([log, tmp_path / "new.csv"], {}, force=True)
    with pytest.raises(InputError, match="given twice"):
        check_outputs([tmp_path / "a", tmp_path / "." / "a"], {}, force=True)
    with pytest.raises(InputError, match="is a folder"):
        check_outputs([tmp_path], {}, force=True)
    with pytest.raises(InputError, match="does not exist"):
        check_outputs([tmp_path / "no" / "a"], {}, force=True)
    check_outputs([tmp_path / "no" / "a"], {}, force=True, folders_made=True)
    with pytest.raises(InputError, match="is a file, not a folder"):
        check_outputs([log / "a"], {}, force=True, folders_made=True)


def test_a_device_is_written_directly(tmp_path):
    """``-o /dev/stdout`` and the like: no file to replace, so no --force and no rename."""
    from fieldcal import _files

    device = Path(os.devnull)
    if not device.exists() or device.is_file():  # pragma: no cover - not a POSIX system
        pytest.skip("no null device")
    _files.check_outputs([device], {}, force=False)
    _files.write_text(device, "nothing\n")
    assert device.exists() and not device.is_file()
