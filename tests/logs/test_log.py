"""The log shapes real users bring: bursty and paused clocks, clocks that reset, slow continuous
turns with no rests (poses cut into windows), sensors under unknown names, big logs.

Every log here is built from a known answer: timestamps whose rate is known, a turning path
through a known calibration (the window means must lie on its ellipsoids), headers whose
sensors are known.
"""

from __future__ import annotations

import importlib
import importlib.util
import re
import warnings

import numpy as np
import pytest
from _logs import _csv, _turning
from hypothesis import given
from hypothesis import strategies as st

from fieldcal.errors import InputError
from fieldcal.logs import load_log, poses_from_log, read_table, recognise_columns
from fieldcal.logs.log import _time_in_seconds, sample_rate
from fieldcal.logs.pose_finding import MOTION_LIMIT, turns_slowly
from fieldcal.simulation.continuous import simulate_continuous


def _one_line(info: pytest.ExceptionInfo[BaseException]) -> str:
    text = str(info.value)
    assert "\n" not in text and len(text) < 600, text
    return text


def _bursts(n: int, rate: float, per_burst: int = 4, spread: float = 0.001) -> np.ndarray:
    """Timestamps of ``rate`` samples per second delivered ``per_burst`` at a time: pairs share
    a timestamp, the next pair comes ``spread`` later, then the gap to the next burst."""
    burst = np.arange(n) // per_burst
    within = (np.arange(n) % per_burst) // 2 * spread
    return 1000.0 + burst * per_burst / rate + within


def _still_log(rate: float = 100.0, seed: int = 3):
    sim = simulate_continuous("paper", seed=seed, rate=rate)
    return sim, dict(sim.columns)


# ----------------------------------------------------------------------------------- time
def test_bursty_clock_gives_the_sample_rate_and_the_windows(tmp_path):
    """98 Hz in bursts of 4 (two pairs 1 ms apart, then a 40 ms gap): the median step is 0,
    the rate (n - 1) / span; still detection's windows in seconds use it."""
    sim, columns = _still_log(rate=98.0)
    n = len(columns["t"])
    columns["t"] = _bursts(n, 98.0)
    log = load_log(_csv(tmp_path / "bursty.csv", columns))
    expected = (n - 1) / (columns["t"][-1] - columns["t"][0])
    assert log.rate == pytest.approx(expected, rel=1e-12)
    assert log.rate == pytest.approx(98.0, rel=0.002)
    poses = poses_from_log(log)
    assert poses.rate == log.rate
    assert poses.detection.window == round(0.5 * expected) | 1  # 0.5 s, made odd
    assert poses.detection.min_samples == round(1.0 * expected)
    assert poses.n == len(sim.segments)


def test_a_pause_of_the_logger_is_left_out_of_the_rate():
    t = _bursts(6000, 99.0)
    t[3000:] += 5.0  # the logger stopped for 5 s
    steps = np.diff(t)
    kept = steps[steps < 1.0]
    assert sample_rate(t) == pytest.approx(len(kept) / kept.sum(), rel=1e-12)
    assert sample_rate(t) == pytest.approx(99.0, rel=0.002)
    fifo = (np.arange(300)[:, None] * 0.2 + np.arange(20) * 1e-4).ravel()  # 20 per 200 ms
    assert sample_rate(fifo) == pytest.approx(len(fifo) / 60.0, rel=0.01)
    assert sample_rate(np.zeros(5)) is None and sample_rate(np.ones(1)) is None


@pytest.mark.parametrize(
    ("name", "factor", "unit"),
    [
        ("time", 1.0, None),
        ("time", 1e3, "milliseconds"),
        ("time", 1e6, "microseconds"),
        ("time", 1e9, "nanoseconds"),
        ("t_ms", 1e3, None),
        ("timestamp_us", 1e6, None),
        ("t_ns", 1e9, None),
    ],
)
def test_time_units_of_a_bursty_clock(name, factor, unit):
    """The unit is read from the name, else from the mean step without pauses: a bursty
    millisecond clock (median step 0.5 ms) is not taken for seconds."""
    t = _bursts(2000, 99.0) - 1000.0
    seconds, note = _time_in_seconds(t * factor, name)
    np.testing.assert_allclose(seconds, t - t[0], rtol=1e-9, atol=1e-12)
    assert (note is None) == (unit is None) and (unit is None or unit in note)


def test_time_going_back_names_the_data_row(tmp_path):
    _, columns = _still_log()
    columns["t"] = columns["t"].copy()
    reset = 1234  # data row 1235: the clock restarts from zero
    columns["t"][reset:] -= columns["t"][reset]
    columns["ax"] = columns["ax"].copy()
    columns["ax"][100] = np.nan  # dropped: kept rows and data rows differ from here
    path = _csv(tmp_path / "reset.csv", columns)
    with pytest.raises(InputError, match=r"goes back by [\d.]+ s at data row 1235") as info:
        load_log(path, drop_nan=True)
    assert "--split-on-reset" in _one_line(info)


def test_jitter_and_repeated_timestamps_are_fine(tmp_path):
    _, columns = _still_log()
    t = columns["t"].copy()
    t[1::50] -= 0.013  # a sample written 3 ms before the one ahead of it
    t[2::7] = t[1::7][: len(t[2::7])]  # repeated timestamps
    columns["t"] = t
    log = load_log(_csv(tmp_path / "jitter.csv", columns))
    assert log.segment is None and log.rate == pytest.approx(100.0, rel=1e-3)


def test_split_on_reset(tmp_path):
    sim, columns = _still_log()
    t = columns["t"].copy()
    start, stop = sim.segments[4]
    reset = (start + stop) // 2  # in the middle of a still pose
    t[reset:] -= t[reset] - 7.0  # restarts at 7 s, within the time already seen
    columns["t"] = t
    log = load_log(_csv(tmp_path / "reset.csv", columns), split_on_reset=True)
    assert np.array_equal(log.segment, (np.arange(len(t)) >= reset).astype(np.int64))
    # each segment keeps its own steps and continues one mean step after the one before
    np.testing.assert_allclose(np.diff(log.time)[: reset - 1], np.diff(t)[: reset - 1])
    np.testing.assert_allclose(np.diff(log.time)[reset:], np.diff(t)[reset:], atol=1e-9)
    assert log.time[reset] - log.time[reset - 1] == pytest.approx(0.01, rel=1e-6)
    assert log.rate == pytest.approx(100.0, rel=1e-6)
    assert any("restarts 1 time" in note for note in log.notes)
    poses = poses_from_log(log)
    for entry in poses.entries:  # no pose spans the reset ...
        assert entry["stop"] <= reset or entry["start"] >= reset
    # ... and the pose it cut is found on both sides
    assert sum(start <= e["start"] and e["stop"] <= stop for e in poses.entries) == 2
    assert poses.n == len(sim.segments) + 1
    # windows never span a reset ("samples": a window given is cut without the motion check,
    # which the moves between this log's rests fail at the 90th percentile)
    windows = poses_from_log(log, poses="samples", window=0.1)
    assert all(e["stop"] <= reset or e["start"] >= reset for e in windows.entries)
    if importlib.util.find_spec("pandas") is not None:  # the pandas view (the pandas extra)
        assert log.to_pandas()["segment"].to_numpy().tolist() == log.segment.tolist()


def test_a_rate_given_wins_and_a_disagreement_is_a_warning(tmp_path):
    _, columns = _still_log()
    log = load_log(_csv(tmp_path / "log.csv", columns))
    pattern = r"rate given \(50 Hz\) and the time column's \(100 Hz\) differ by 50%"
    with pytest.warns(UserWarning, match=pattern):
        poses = poses_from_log(log, rate=50.0)
    assert poses.rate == 50.0 and poses.detection.window == 25
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # 3 % apart: no warning, and no numpy warning either
        poses = poses_from_log(log, rate=103.0)
    assert poses.rate == 103.0 and poses.detection.window == round(0.5 * 103.0) | 1


# -------------------------------------------------------------------------------- windows


def _calibrated(means, K, b):
    return np.linalg.solve(K, (np.asarray(means) - b).T).T


def test_windows_of_a_slow_turn_lie_on_the_ellipsoids(tmp_path):
    columns, (Ka, ba, Km, bm) = _turning(0)
    log = load_log(_csv(tmp_path / "turn.csv", columns))
    assert turns_slowly(log)
    # no rests: still detection's "still" intervals are slices of the turn, and it says so
    with pytest.warns(UserWarning, match=r"the still intervals found move: .* windows$"):
        poses_from_log(log)
    poses = poses_from_log(log, poses="windows")
    assert poses.n == 240 and poses.source == "windows"  # 60 s of 0.25 s windows
    assert poses.windows.window == 25 and poses.windows.seconds == 0.25
    assert poses.windows.motion < MOTION_LIMIT
    record = poses.record()
    assert record["source"] == "windows" and record["window_s"] == 0.25
    assert record["rate_hz"] == pytest.approx(100.0)
    for i, entry in enumerate(poses.entries):
        assert (entry["start"], entry["stop"], entry["samples"]) == (25 * i, 25 * i + 25, 25)
        assert entry["std"] == pytest.approx(np.sqrt(np.mean(poses.accel[i].var(axis=0))))
    ua = _calibrated([p.mean(axis=0) for p in poses.accel], Ka, ba)
    um = _calibrated([p.mean(axis=0) for p in poses.mag], Km, bm)
    # on the unit sphere to the noise of a 25-sample mean (0.0008 per axis: 6 sigma), with
    # no shrinkage beyond a 3° arc's 1e-4
    radial = np.linalg.norm(ua, axis=1) - 1.0
    assert np.max(np.abs(radial)) < 0.005 and abs(np.mean(radial)) < 5e-4
    radial = np.linalg.norm(um, axis=1) / 50.0 - 1.0
    assert np.max(np.abs(radial)) < 0.01 and abs(np.mean(radial)) < 1e-3
    cos = np.sum(ua * um, axis=1) / np.linalg.norm(ua, axis=1) / np.linalg.norm(um, axis=1)
    angle = np.degrees(np.arccos(cos))  # 90° + the 60° dip in every window
    assert abs(np.mean(angle) - 150.0) < 0.05 and np.max(np.abs(angle - 150.0)) < 1.0
    assert len({e["orientation"] for e in poses.entries}) > 100


def test_a_fast_turn_is_refused_and_the_suggested_window_works(tmp_path):
    columns, _ = _turning(1, speed_deg=60.0, seconds=20.0)
    log = load_log(_csv(tmp_path / "fast.csv", columns))
    assert not turns_slowly(log)
    with pytest.raises(InputError, match=r"moves too fast for 0\.25 s windows") as info:
        poses_from_log(log, poses="windows")
    text = _one_line(info)
    ratio = float(re.search(r"moves ([\d.]+)% of \|g\|", text)[1]) / 100
    assert ratio > MOTION_LIMIT and "limit is 5%" in text and "turn more slowly" in text
    shorter = float(re.search(r"give --window ([\d.]+) \(seconds\)", text)[1])
    poses = poses_from_log(log, poses="windows", window=shorter)
    assert poses.windows.motion < MOTION_LIMIT
    # the motion grows with the window: about in proportion
    assert ratio * shorter / 0.25 == pytest.approx(poses.windows.motion, rel=0.35)


def test_a_log_of_still_poses_does_not_turn_slowly(tmp_path):
    _, columns = _still_log()
    assert not turns_slowly(load_log(_csv(tmp_path / "still.csv", columns)))


def test_windows_of_a_magnetometer_alone_use_the_field_norm(tmp_path):
    """The magnetometer's offset is three times its field: the motion is measured against
    the field (half the range of the window means), not the offset."""
    columns, (_, _, Km, bm) = _turning(2, mag_noise=0.2, mag_bias=150.0)
    mag_only = {k: v for k, v in columns.items() if k[0] in "tm"}
    log = load_log(_csv(tmp_path / "mag.csv", mag_only))
    assert log.accel is None and turns_slowly(log)
    poses = poses_from_log(log, poses="windows")
    assert poses.accel is None and poses.windows.sensor == "mag"
    # the field turns as the accelerometer's gravity did: a motion of the same size, not
    # one divided by the 3x larger offset (at the 90th percentile the two directions' turns
    # differ by up to a third: a turn about the field moves gravity only)
    both = poses_from_log(load_log(_csv(tmp_path / "both.csv", columns)), poses="windows")
    assert poses.windows.drift == pytest.approx(both.windows.drift, rel=0.4)
    um = _calibrated([p.mean(axis=0) for p in poses.mag], Km, bm)
    assert np.max(np.abs(np.linalg.norm(um, axis=1) / 50.0 - 1.0)) < 0.01


def test_windows_override_a_pose_column_only_when_asked(tmp_path):
    columns, _ = _turning(3, seconds=10.0)
    columns["pose"] = np.arange(len(columns["t"])) // 500
    log = load_log(_csv(tmp_path / "labelled.csv", columns))
    assert poses_from_log(log).source == "column" and poses_from_log(log).n == 2
    assert poses_from_log(log, poses="windows").n == 40
    with pytest.raises(InputError, match="poses must be one of still, windows"):
        poses_from_log(log, poses="rests")


def test_window_options_are_checked(tmp_path):
    columns, _ = _turning(4, seconds=5.0)
    log = load_log(_csv(tmp_path / "short.csv", columns))
    with pytest.raises(InputError, match="gives 2 sample") as info:
        poses_from_log(log, poses="windows", window=0.02)
    _one_line(info)
    with pytest.raises(InputError, match="longer than the log"):
        poses_from_log(log, poses="windows", window=60.0)


def test_ten_thousand_poses_cut_the_same_by_windows_and_labels():
    """2·10⁵ rows cut into 10⁴ windows, and 10⁴ labels of a pose column, alike (the time is
    measured in benchmarks/, never asserted here)."""
    columns, _ = _turning(5, seconds=20.0, speed_deg=3.0)
    rows = {k: np.tile(v, 100) for k, v in columns.items()}
    rows["t"] = np.arange(len(rows["t"])) / 100.0
    rows["pose"] = np.arange(len(rows["t"])) // 20
    table = read_table_from(rows)
    log = load_log(table)
    windows = poses_from_log(log, poses="windows", window=0.2)
    grouped = poses_from_log(log)
    assert windows.n == grouped.n == 10_000
    assert [e["start"] for e in windows.entries] == [e["start"] for e in grouped.entries]


def read_table_from(columns: dict[str, np.ndarray]):
    from fieldcal.logs.readers import Table

    return Table("<memory>", list(columns), {k: np.asarray(v) for k, v in columns.items()})


# -------------------------------------------------------------------------------- columns
def _triple(spelling: str) -> list[str]:
    """``"acc_{}[m/s^2]"`` -> the three names with x, y, z (X, Y, Z for ``{X}``)."""
    if "{X}" in spelling:
        return [spelling.replace("{X}", a) for a in "XYZ"]
    return [spelling.replace("{}", a) for a in "xyz"]


@pytest.mark.parametrize(
    ("accel", "mag", "gyro"),
    [
        ("acc{X}", None, None),
        ("Acc{X} (g)", None, None),
        ("acc_{}[m/s^2]", None, None),
        (None, "Mag_{X}_uT", None),
        (None, "mag{X}", None),
        ("imu.linear_acceleration.{}", None, "imu.angular_velocity.{}"),
        ("LSM9DS1 a{}", "LSM9DS1 m{}", "LSM9DS1 g{}"),
        ("Ac{X}", None, "Gy{X}"),  # MPU-6050 sketches
        ("{}_acc", "{}_mag", None),
        ("accel[{}]".replace("{}", "{i}"), None, None),
        ("gravity.{}", "magneticField.{}", "rotationRate.{}"),  # iOS CoreMotion
        ("Acceleration {} (m/s^2)", "Magnetic field {} (µT)", None),  # phyphox
        ("ACCELEROMETER {X} (m/s²)", "MAGNETIC FIELD {X} (μT)", "GYROSCOPE {X} (rad/s)"),
    ],
)
def test_real_headers(accel, mag, gyro):
    names, expected = ["time", "temperature"], {}
    for role, spelling in (("accel", accel), ("mag", mag), ("gyro", gyro)):
        if spelling is not None:
            triple = (
                [spelling.replace("{i}", i) for i in "012"]
                if "{i}" in spelling
                else _triple(spelling)
            )
            names += triple
            expected[role] = triple
    found = recognise_columns(names)
    assert {k: v for k, v in found.items() if k in ("accel", "mag", "gyro")} == expected


@pytest.mark.parametrize(
    "names",
    [
        _triple("lin_acc_{}"),  # gravity taken out (Android's, the BNO055's): not raw readings
        _triple("userAcceleration.{}"),  # iOS's, the same
        ["max", "may", "maz"],
        _triple("pos_{}"),
    ],
)
def test_headers_that_are_not_sensors(names):
    assert recognise_columns(names) == {}


_ACCEL = ["a", "acc", "accel", "Acc", "ACCEL", "accelerometer", "linear_acceleration"]
_MAG = ["m", "mag", "Mag", "magn", "magnetometer", "magnetic_field", "compass"]


@given(
    st.sampled_from(_ACCEL),
    st.sampled_from(_MAG),
    st.sampled_from(["", "_", ".", " "]),
    st.sampled_from(["", " (g)", "_raw", "[m/s^2]", "_uT"]),
    st.sampled_from(["", "imu.", "LSM9DS1 ", "sensor2_"]),
    st.booleans(),
    st.permutations(range(9)),
)
def test_sensor_spellings_are_recognised_in_any_order(accel, mag, sep, unit, device, upper, order):
    """Each sensor's x, y, z share a spelling: found whatever the case, separator, unit,
    device name and column order, beside a time and a temperature."""
    axes = "XYZ" if upper else "xyz"
    a = [f"{device}{accel}{sep}{x}{unit}" for x in axes]
    m = [f"{device}{mag}{sep}{x}{unit}" for x in axes]
    names = [*a, *m, "time", "temperature", "pressure"]
    shuffled = [names[i] for i in order] + names[9:]
    found = recognise_columns(shuffled)
    assert found["accel"] == a and found["mag"] == m and found["time"] == ["time"]


@pytest.mark.parametrize(
    ("names", "seen"),
    [
        (["t", "ax", "ay", "az", "tx", "ty", "tz"], "tx,ty,tz"),
        (["ax", "ay", "az", "sensor2_x", "sensor2_y", "sensor2_z"], "sensor2_x,sensor2_y,"),
        (["mx", "my", "mz", "X", "Y", "Z"], "X,Y,Z"),
        (["time", "Bx", "By", "Bz", "accX_raw_adc", "accY_raw_adc", "accZ_raw_adc"], None),
    ],
)
def test_an_unrecognised_second_sensor_is_an_error(tmp_path, names, seen):
    values = np.random.default_rng(0).normal(size=(20, len(names)))
    values[:, 0] = np.arange(20)  # the first column may be the time
    path = _csv(tmp_path / "log.csv", dict(zip(names, values.T, strict=True)))
    if seen is None:  # a magnetometer named B: the accelerometer is found, B is unknown
        seen = "Bx,By,Bz"
    with pytest.raises(InputError, match="look like another sensor's x,y,z") as info:
        load_log(path)
    text = _one_line(info)
    assert seen in text and "--mag-cols" in text and "--accel-cols" in text
    assert "names understood: ax, acc_x" in text and f"columns: {names[0]}" in text


@pytest.mark.parametrize(
    "names",
    [
        ["t", "mx", "my", "mz"],
        ["mx", "my", "mz", "temperature", "pressure", "humidity"],
        ["t", "ax", "ay", "az", "qw", "qx", "qy", "qz"],  # an orientation estimate
        ["t", "ax", "ay", "az", "gx", "gy", "gz", "pos_x", "pos_y", "pos_z"],
        ["ax", "ay", "az", "ax_std", "ay_std", "az_std"],
    ],
)
def test_a_genuine_one_sensor_log_still_loads(tmp_path, names):
    values = np.random.default_rng(1).normal(size=(20, len(names)))
    values[:, 0] = np.arange(20)  # the first column may be the time
    log = load_log(_csv(tmp_path / "log.csv", dict(zip(names, values.T, strict=True))))
    assert (log.accel is None) != (log.mag is None)


def test_explicit_columns_override(tmp_path):
    names = ["t", "ax", "ay", "az", "tx", "ty", "tz"]
    values = np.random.default_rng(2).normal(size=(20, 7))
    values[:, 0] = np.arange(20)
    path = _csv(tmp_path / "log.csv", dict(zip(names, values.T, strict=True)))
    log = load_log(path, mag_cols="tx,ty,tz")
    np.testing.assert_array_equal(log.mag, values[:, 4:])
    log = load_log(path, accel_cols="ax,ay,az")  # the accelerometer alone, on purpose
    assert log.mag is None and log.used["accel"] == ["ax", "ay", "az"]


# ----------------------------------------------------------------------------- the Log
def test_a_table_in_memory_and_to_pandas(tmp_path):
    pd = pytest.importorskip("pandas", reason="pandas (the pandas extra) not installed")
    _, columns = _still_log()
    columns["ax"] = columns["ax"].copy()
    columns["ax"][5] = np.nan
    columns["pose"] = np.arange(len(columns["t"])) // 100
    log = load_log(read_table_from(columns), drop_nan=True)
    assert log.path == "<memory>" and log.n == len(columns["t"]) - 1
    frame = log.to_pandas()
    assert isinstance(frame, pd.DataFrame)
    expected = ["t", "ax", "ay", "az", "mx", "my", "mz", "gx", "gy", "gz", "pose"]
    assert list(frame.columns) == expected and frame.index.name == "data_row"
    assert frame.index[4] == 5 and frame.index[5] == 7  # data row 6 (the NaN) dropped
    np.testing.assert_array_equal(frame["my"].to_numpy(), log.mag[:, 1])
    np.testing.assert_array_equal(frame["t"].to_numpy(), log.time)
    # the same log read from a file
    again = load_log(_csv(tmp_path / "log.csv", columns), drop_nan=True)
    np.testing.assert_array_equal(again.accel, log.accel)


def test_to_pandas_without_pandas(monkeypatch, tmp_path):
    log = load_log(_csv(tmp_path / "log.csv", {"ax": [1.0], "ay": [2.0], "az": [3.0]}))
    real = importlib.import_module

    def missing(name, *args):
        if name == "pandas":
            raise ImportError("No module named 'pandas'")
        return real(name, *args)

    monkeypatch.setattr(importlib, "import_module", missing)
    with pytest.raises(InputError, match="pip install pandas"):
        log.to_pandas()


def test_an_every_row_finite_log_is_not_copied_twice(tmp_path):
    """No row selection when every row is kept: the arrays are the stacked columns."""
    table = read_table(
        _csv(
            tmp_path / "log.csv",
            {"t": np.arange(5.0), "mx": np.ones(5), "my": np.ones(5), "mz": np.ones(5)},
        )
    )
    log = load_log(table)
    assert log.mag.flags.c_contiguous and log.mag.base is None
    assert np.array_equal(log.index, np.arange(5)) and log.dropped == 0


def _both(n=20, drop=()):
    rng = np.random.default_rng(4)
    columns = {name: rng.normal(size=n) for name in ("ax", "ay", "az", "mx", "my", "mz")}
    return {k: v for k, v in columns.items() if k not in drop}


@pytest.mark.parametrize(
    ("drop", "message"),
    [
        (("ax",), "the accelerometer's x column is missing (ay, az are recognised"),
        (("mz",), "the magnetometer's z column is missing (mx, my are recognised"),
    ],
)
def test_a_sensor_missing_an_axis_is_an_error_naming_it(tmp_path, drop, message):
    """Not silently a one-sensor fit: the missing column and both fixes are named."""
    path = _csv(tmp_path / "log.csv", _both(drop=drop))
    with pytest.raises(InputError) as info:
        load_log(path)
    assert message in str(info.value) and "\n" not in str(info.value)
    other = "mag" if drop == ("ax",) else "accel"
    assert f"--sensors {other}" in str(info.value)
    # asked for the other sensor alone (the option, or its columns only): read
    log = load_log(path, sensors=other)
    assert getattr(log, other) is not None and log.used.keys() <= {other}
    cols = "mx,my,mz" if other == "mag" else "ax,ay,az"
    assert load_log(path, **{f"{other}_cols": cols}).used.keys() == {other}


def test_sensors_option(tmp_path):
    path = _csv(tmp_path / "log.csv", _both())
    assert load_log(path, sensors="accel").mag is None
    assert load_log(path, sensors="mag").accel is None
    assert load_log(path, sensors="both").accel is not None
    only_mag = _csv(tmp_path / "mag.csv", _both(drop=("ax", "ay", "az")))
    assert load_log(only_mag).accel is None  # no trace of an accelerometer: one sensor, as before
    with pytest.raises(InputError, match="--sensors both but no accelerometer columns"):
        load_log(only_mag, sensors="both")
    with pytest.raises(InputError, match="--sensors accel but no accelerometer"):
        load_log(only_mag, sensors="accel")
    with pytest.raises(InputError, match="sensors must be 'accel', 'mag' or 'both'"):
        load_log(path, sensors="gyro")
    one_axis = _csv(tmp_path / "az.csv", _both(drop=("ax", "ay")))  # az alone: an azimuth?
    assert load_log(one_axis).accel is None
