"""The library's path from a log to a calibration: ``fieldcal.read_log`` and
``fieldcal.calibrate_log`` on a file, a DataFrame, a mapping and a Log, as the CLI does it;
an accelerometer that reports gravity."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

import fieldcal
from fieldcal.cli import cli
from fieldcal.errors import InputError
from fieldcal.geometry.rotations import rotation_angle_deg
from fieldcal.simulation.continuous import simulate_continuous


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A simulated continuous log (Table 1 sensors) as a CSV file and as its columns."""
    sim = simulate_continuous("paper", seed=3)
    path = tmp_path_factory.mktemp("log") / "session.csv"
    sim.write_csv(str(path))
    # the columns as written (the CSV rounds to 9 digits), so every source holds one log
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return path, {name: data[:, j] for j, name in enumerate(sim.columns)}


def _same(a: fieldcal.Calibration, b: fieldcal.Calibration) -> None:
    for sensor in ("accel", "mag"):
        np.testing.assert_allclose(a.sensor(sensor).gain, b.sensor(sensor).gain, atol=1e-12)
        np.testing.assert_allclose(a.sensor(sensor).bias, b.sensor(sensor).bias, atol=1e-12)


def test_every_source_gives_the_cli_result(session, tmp_path):
    """A path, a mapping of columns, a DataFrame and a Log read first give one calibration,
    the one ``fieldcal calibrate`` writes."""
    path, columns = session
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(cli, ["calibrate", str(path), "-o", str(out), "-q"])
    assert result.exit_code == 0, result.output
    from_cli = fieldcal.Calibration.from_json(out.read_text())
    from_path = fieldcal.calibrate_log(path)
    _same(from_cli, from_path)
    _same(from_path, fieldcal.calibrate_log(str(path)))
    _same(from_path, fieldcal.calibrate_log(columns))
    _same(from_path, fieldcal.calibrate_log(fieldcal.read_log(path)))
    pandas = pytest.importorskip("pandas", reason="pandas (the pandas extra) not installed")
    _same(from_path, fieldcal.calibrate_log(pandas.DataFrame(columns)))
    # the poses are listed with their rows in the log, as in the CLI's JSON
    assert [p["start"] for p in from_path.poses] == [p["start"] for p in from_cli.poses]


def test_read_log_takes_column_names_and_tables(session):
    path, columns = session
    renamed = {("tx" if k == "ax" else k): v for k, v in columns.items()}
    log = fieldcal.read_log(renamed, accel_cols="tx,ay,az")
    assert log.used["accel"] == ["tx", "ay", "az"]
    np.testing.assert_array_equal(log.accel[:, 0], columns["ax"])
    pyarrow = pytest.importorskip("pyarrow", reason="pyarrow (the parquet extra) not installed")
    table = fieldcal.read_log(pyarrow.table(columns))
    np.testing.assert_array_equal(table.mag, fieldcal.read_log(path).mag)


@pytest.mark.parametrize(
    ("source", "match"),
    [
        (42, "cannot read a log from a int"),
        ({"ax": [1.0, 2.0], "ay": [1.0]}, "different lengths"),
        ({}, "no columns"),
        ({"ax": np.zeros((2, 2))}, "1-D column"),
    ],
)
def test_bad_sources_are_one_line_errors(source, match):
    with pytest.raises(InputError, match=match):
        fieldcal.read_log(source)


def test_bad_choices_are_one_line_errors(session):
    path, _ = session
    with pytest.raises(InputError, match=r"poses \(--poses\) must be one of 'auto', 'still'"):
        fieldcal.calibrate_log(path, poses="rests")
    with pytest.raises(InputError, match=r"accel_sign \(--accel-sign\) must be one of"):
        fieldcal.calibrate_log(path, accel_sign="down")


def test_an_accelerometer_reporting_gravity(session, tmp_path):
    """A logger that reports gravity (−1 g up) is its specific force negated. Read with
    accel_sign="gravity", the calibration is the specific-force one expressed for the raw
    columns (gain and bias negated), corrects them to the same specific force, keeps the dip
    and its error bars; read without, the dip flips sign and the verdict names the cause."""
    _, columns = session
    flipped = {k: (-v if k in ("ax", "ay", "az") else v) for k, v in columns.items()}
    plain = fieldcal.calibrate_log(columns)
    folded = fieldcal.calibrate_log(flipped, accel_sign="gravity")
    np.testing.assert_allclose(folded.accel.gain, -plain.accel.gain, atol=1e-12)
    np.testing.assert_allclose(folded.accel.bias, -plain.accel.bias, atol=1e-12)
    np.testing.assert_allclose(folded.accel.noise_cov, plain.accel.noise_cov, atol=1e-15)
    np.testing.assert_allclose(folded.accel.gain_std, plain.accel.gain_std, rtol=1e-9)
    raw = np.column_stack([columns[c] for c in ("ax", "ay", "az")])
    np.testing.assert_allclose(folded.correct_accel(-raw), plain.correct_accel(raw), atol=1e-12)
    assert folded.dip_deg == pytest.approx(plain.dip_deg, abs=1e-9)
    assert folded.options["accel_sign"] == "gravity"
    assert fieldcal.Calibration.from_json(folded.to_json()) == folded

    naive = fieldcal.calibrate_log(flipped)
    assert naive.dip_deg == pytest.approx(-plain.dip_deg, abs=1e-6)
    negative = naive if naive.dip_deg < 0 else plain
    assert "negative_dip" in negative.verdict.codes

    # the CLI option does the same and says so
    csv = tmp_path / "gravity.csv"
    names = list(flipped)
    np.savetxt(csv, np.column_stack([flipped[n] for n in names]), delimiter=",",
               header=",".join(names), comments="", fmt="%.10g")  # fmt: skip
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(
        cli, ["calibrate", str(csv), "-o", str(out), "--accel-sign", "gravity"]
    )
    assert result.exit_code == 0, result.output
    assert "reporting gravity" in result.output
    doc = json.loads(out.read_text())
    assert doc["options"]["accel_sign"] == "gravity"
    np.testing.assert_allclose(doc["accel"]["gain"], folded.accel.gain, rtol=1e-6, atol=1e-9)


def test_calibrate_log_leaves_the_log_alone(session):
    path, _ = session
    log = fieldcal.read_log(path)
    before = dataclasses.replace(log, accel=log.accel.copy(), mag=log.mag.copy())
    fieldcal.calibrate_log(log, accel_sign="gravity", mag_axes="+x+y+z")
    np.testing.assert_array_equal(log.accel, before.accel)
    np.testing.assert_array_equal(log.mag, before.mag)


def test_a_slow_turn_calibrates_in_windows(tmp_path):
    """A board turned slowly with no rests (the Magneto/MotionCal way): ``poses="windows"``
    recovers the calibration — the gauge-free ``K Kᵀ`` and the bias of each sensor, the dip —
    and the CLI's ``--poses windows`` gives the same and records the windows in the JSON."""
    from _logs import _csv, _turning

    columns, (Ka, ba, Km, bm) = _turning(4)
    cal = fieldcal.calibrate_log(columns, poses="windows", field_strength=50.0)
    assert cal.verdict.level != "fail"
    for sensor, K, b in (("accel", Ka, ba), ("mag", Km, bm)):
        fitted = cal.sensor(sensor)
        gram, true_gram = fitted.gain @ fitted.gain.T, K @ K.T
        assert np.max(np.abs(gram - true_gram)) < 0.01 * np.max(np.abs(true_gram))
        # within 5 of its own standard errors: the motion inside the windows adds no bias
        assert np.all(np.abs(fitted.bias - b) < 5 * fitted.bias_std)
    assert abs(abs(cal.dip_deg) - 60.0) < 0.3

    path = _csv(tmp_path / "turn.csv", columns)
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(
        cli, ["calibrate", str(path), "--poses", "windows", "-o", str(out), "--field-strength",
              "50"],
    )  # fmt: skip
    assert result.exit_code in (0, 3), result.output
    assert "cut into 0.25 s windows" in result.output
    doc = json.loads(out.read_text())
    assert doc["pose_windows"]["source"] == "windows" and doc["pose_windows"]["count"] == 240
    np.testing.assert_allclose(doc["mag"]["gain"], cal.mag.gain, rtol=1e-6, atol=1e-9)


def test_poses_found_first_take_the_axis_map_and_the_sign(session):
    """Poses found before the call (as the live capture passes them) give the calibration the
    whole path gives with an axis map and a gravity-reporting accelerometer: neither moves a
    still interval, and both reach the poses' samples."""
    from fieldcal.logs.pose_finding import poses_from_log
    from fieldcal.pipeline import LogSettings, run_log

    _, columns = session
    flipped = dict(columns)
    for axis in "xyz":
        flipped[f"a{axis}"] = -columns[f"a{axis}"]
    # the magnetometer wired +y+x-z relative to the accelerometer
    flipped["mx"], flipped["my"], flipped["mz"] = columns["my"], columns["mx"], -columns["mz"]
    log = fieldcal.read_log(flipped)
    settings = LogSettings.of(mag_axes="+y+x-z", accel_sign="gravity")
    whole = run_log(log, settings).calibration
    given = run_log(log, settings, found=poses_from_log(log)).calibration
    _same(whole, given)
    plain = fieldcal.calibrate_log(columns)
    np.testing.assert_allclose(whole.dip_deg, plain.dip_deg, atol=1e-9)


def test_the_gyroscope_from_the_same_log(tmp_path):
    """A continuous log with a gyroscope: ``calibrate_log`` fits it from the motion between
    the poses, the truth (in fieldcal's body frame) lies within 4 standard errors, it travels
    through the JSON and the CLI, and ``gyro=`` skips it or makes any reason an error."""
    sim = simulate_continuous("paper", seed=21)
    truth = sim.gyro_truth
    path = tmp_path / "gyro.csv"
    sim.write_csv(str(path))
    cal = fieldcal.calibrate_log(path)
    assert cal.gyro is not None and cal.options["gyro"]["method"] == "rotations"
    z_gain = (cal.gyro.gain - truth.gain) / cal.gyro.gain_std
    z_bias = (cal.gyro.bias - truth.bias) / cal.gyro.bias_std
    assert np.abs(z_gain).max() < 4 and np.abs(z_bias).max() < 4, (z_gain, z_bias)
    assert len(cal.gyro_segments) == len(sim.segments) - 1
    # each segment's turn, integrated by the calibrated gyroscope, is the simulated one (the
    # residual angles run to about a degree)
    R = np.asarray(sim.session.drawn["rotations"])
    true_turns = rotation_angle_deg(R[1:] @ np.swapaxes(R[:-1], 1, 2))
    turns = [s["angle_deg"] for s in cal.gyro_segments]
    np.testing.assert_allclose(turns, true_turns, atol=3.0)
    # the accelerometer alone: the gravity directions determine the bias as well
    alone = fieldcal.calibrate_log({k: v for k, v in sim.columns.items() if k[0] != "m"})
    assert alone.options["gyro"]["method"] == "gravity"
    assert np.abs((alone.gyro.bias - truth.bias) / alone.gyro.bias_std).max() < 4
    again = fieldcal.Calibration.from_json(cal.to_json())
    rates = np.column_stack([sim.columns[f"g{a}"] for a in "xyz"])
    np.testing.assert_allclose(again.correct_gyro(rates), cal.correct_gyro(rates), atol=1e-12)
    assert fieldcal.calibrate_log(path, gyro=False).gyro is None
    no_gyro = {k: v for k, v in sim.columns.items() if not k.startswith("g")}
    with pytest.raises(InputError, match="no gyroscope columns"):
        fieldcal.calibrate_log(no_gyro, gyro=True)
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(cli, ["calibrate", str(path), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "gyroscope: raw = gain · ω (rad/s) + bias" in result.output
    assert json.loads(out.read_text())["gyro"]["gain"] == [list(r) for r in cal.gyro.gain]


def test_slow_sparse_logs_calibrate_per_sample_with_honest_error_bars():
    """Magneto-like logs (acc+mag at 3 rows/s, no time column, turned slowly by a hand whose
    acceleration is shared by neighbouring samples): ``poses="samples"`` calibrates them, the
    error bars are widened for the correlation measured between neighbours, and the 95 %
    intervals of every gain, bias and the dip cover about 95 % of a small seeded batch (6 logs
    x 25 parameters: 150 draws, binomial s.d. 1.8 %); without the widening they would not."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import slow_turns

    z_fit, z_before = [], []
    for seed in range(6):
        columns, truth = slow_turns.slow_turn_log(200 + seed, rate=3.0, seconds=120.0)
        found = slow_turns.calibrate_columns(
            columns, "samples", time_column=False, gravity=9.80665, field_strength=48.0
        )
        cal = found.calibration
        assert found.poses.n == 360 and found.poses.source == "samples"
        # the χ² certificate is no test here, and the verdict says so by its code
        assert "correlated_poses" in [r.code for r in cal.verdict.reasons]
        assert cal.diagnostics.status == "correlated poses"
        record = cal.options["pose_correlation"]
        assert record["tau"] > 1.0 and record["poses"] == 360
        z_fit.append(slow_turns.z_scores(cal, truth))
        z_before.append(slow_turns.z_scores(cal, truth, unwiden=True))
    cover = float(np.mean(np.abs(np.concatenate(z_fit)) < 1.96))
    before = float(np.mean(np.abs(np.concatenate(z_before)) < 1.96))
    assert 0.88 <= cover <= 1.0, cover
    assert before < cover - 0.03, (before, cover)


def test_samples_on_the_command_line(tmp_path):
    """``--poses samples`` on a log with no time column: one pose per row, the correlation in
    the JSON and the summary."""
    from _logs import _csv, _turning

    columns, _ = _turning(8, seconds=120.0, speed_deg=20.0)
    sparse = {k: v[::33] for k, v in columns.items() if k != "t"}
    path = _csv(tmp_path / "sparse.csv", sparse)
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(cli, ["calibrate", str(path), "--poses", "samples", "-o", str(out)])
    assert result.exit_code in (0, 3), result.output
    assert "one per sample" in result.output and "correlated" in result.output
    doc = json.loads(out.read_text())
    assert doc["pose_samples"] == {"source": "samples", "samples_per_pose": 1, "rate_hz": None}
    assert doc["options"]["pose_correlation"]["poses"] == len(sparse["ax"])
