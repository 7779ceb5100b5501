"""Errors that name the user's mistake, each followed by the fix it names, which succeeds:
not a CSV (JSON, Markdown, binary), swapped arguments, a --rate that contradicts the log, a
gyroscope in deg/s, a hand-waved log without a gyroscope, a Magneto-style log, a shot log, a
clock that steps back a little or resets (issue 34, item 8)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from _cli import run, user_error
from _logs import _csv

from fieldcal.simulation.handwave import simulate_handwave


@pytest.fixture(scope="module")
def waved(tmp_path_factory):
    """Half a minute of hand-waving (no rests): columns t, ax.., gx.., mx.. in rad/s."""
    return simulate_handwave(seed=3, seconds=30.0).columns


def _without(columns, *names):
    return {k: v for k, v in columns.items() if k not in names}


def test_a_calibration_json_a_markdown_note_and_a_binary_file_are_named(tmp_path, waved):
    log = _csv(tmp_path / "log.csv", waved)
    cal = tmp_path / "cal.json"
    run("calibrate", log, "-o", cal, "--quiet")
    user_error("calibrate", cal, "-o", tmp_path / "x.json", match="is a calibration JSON")
    (tmp_path / "other.json").write_text(json.dumps([{"a": 1}]))
    x = ("-o", tmp_path / "x.json")
    user_error("calibrate", tmp_path / "other.json", *x, match="is a JSON document, not a CSV log")
    (tmp_path / "notes.md").write_text("# Setup\n\n| a | b |\n|---|---|\n| 1 | 2 |\n")
    user_error("calibrate", tmp_path / "notes.md", *x, match="looks like Markdown")
    (tmp_path / "blob.dat").write_bytes(b"\x00\x01binary\x00" * 50)
    user_error("calibrate", tmp_path / "blob.dat", *x, match="not a text file (binary")
    (tmp_path / "flight.csv").write_bytes(b"ULog\x01\x12\x35" + b"\x00" * 100)
    user_error("calibrate", tmp_path / "flight.csv", *x, match="PX4 ULog flight log")


def test_apply_and_report_with_their_arguments_swapped(tmp_path, waved):
    log = _csv(tmp_path / "log.csv", waved)
    cal = tmp_path / "cal.json"
    run("calibrate", log, "-o", cal, "--quiet")
    out = tmp_path / "out.csv"
    line = user_error("apply", log, cal, "-o", out, match="the arguments are swapped")
    assert f"fieldcal apply {cal} {log}" in line
    user_error("report", log, cal, "-o", tmp_path / "r.html", match="the arguments are swapped")
    user_error("apply", log, log, "-o", out, match="is not a calibration JSON (its first line")
    run("apply", cal, log, "-o", out, "--quiet")  # the order it names works
    assert out.read_text().splitlines()[0].endswith("mz_cal,gx_cal,gy_cal,gz_cal")


def test_a_gyroscope_in_degrees_per_second_is_detected_and_the_unit_fixes_it(tmp_path, waved):
    columns = dict(waved)
    for axis in "xyz":
        columns[f"g{axis}"] = np.degrees(waved[f"g{axis}"])
    log = _csv(tmp_path / "deg.csv", columns)
    x = ("-o", tmp_path / "x.json")
    line = user_error("calibrate", log, *x, match="--gyro-unit deg/s")
    ratio = float(line.split("integrated turn is ")[1].split(" times")[0])
    assert 0.6 * 57.3 < ratio < 1.6 * 57.3  # the factor measured, not assumed
    user_error("calibrate", log, "--poses", "continuous", *x, match="--gyro-unit deg/s")
    cal = tmp_path / "cal.json"
    run("calibrate", log, "-o", cal, "--gyro-unit", "deg/s", "--quiet")
    doc = json.loads(cal.read_text())
    assert doc["verdict"]["level"] == "pass"
    # folded back: the gain applies to the deg/s columns, about 57.3 raw units per rad/s
    gain = np.asarray(doc["gyro"]["gain"])
    assert np.all(np.abs(np.diag(gain) / math.degrees(1.0) - 1) < 0.05)
    assert doc["options"]["gyro_unit"] == "deg/s"


def test_a_rate_that_contradicts_the_log_names_the_rate_it_shows(tmp_path, waved):
    log = _csv(tmp_path / "notime.csv", _without(waved, "t"))
    x = ("-o", tmp_path / "x.json")
    line = user_error("calibrate", log, "--rate", 1000, *x, match="--rate 1000 contradicts the log")
    hz = float(line.split("the samples come at about ")[1].split(" Hz")[0])
    assert 80 < hz < 120  # the simulation's 100 Hz
    run("calibrate", log, "--rate", 100, "-o", tmp_path / "c.json", "--quiet")
    timed = _csv(tmp_path / "timed.csv", waved)
    user_error("calibrate", timed, "--rate", 1000, *x, match="contradicts the log's time column")


def test_a_hand_waved_log_without_a_gyroscope_says_it_needs_one_or_rests(tmp_path, waved):
    log = _csv(tmp_path / "nogyro.csv", _without(waved, "gx", "gy", "gz"))
    line = user_error("calibrate", log, "-o", tmp_path / "x.json", match="only with a gyroscope")
    assert "--gyro-cols" in line and "record rests" in line
    # the fix it names: the gyroscope's columns
    run("calibrate", _csv(tmp_path / "with.csv", waved), "-o", tmp_path / "c.json", "--quiet")


def test_a_magneto_style_log_is_pointed_to_poses_samples(tmp_path, waved):
    columns = {k: v[::40] for k, v in _without(waved, "t", "gx", "gy", "gz").items()}
    log = _csv(tmp_path / "magneto.csv", columns)
    user_error("calibrate", log, "-o", tmp_path / "x.json", match="use --poses samples")
    cal = tmp_path / "c.json"
    run("calibrate", log, "--poses", "samples", "-o", cal, "--quiet")
    assert json.loads(cal.read_text())["verdict"]["level"] in ("pass", "warn")


def test_a_shot_log_names_its_shot_column(shared_data, tmp_path):
    rows = (shared_data("sap6") / "derived" / "sap6_shots.csv").read_text().splitlines()
    one = [rows[0]] + [r for r in rows[1:] if r.startswith("BB,")]
    log = tmp_path / "bb.csv"
    log.write_text("\n".join(one) + "\n")
    user_error("calibrate", log, "-o", tmp_path / "x.json", match="with --pose-col shot: 24 poses")
    run("calibrate", log, "--pose-col", "shot", "-o", tmp_path / "c.json", "--quiet", ok=False)
    assert (tmp_path / "c.json").exists()


def test_time_jitter_is_spread_and_a_reset_names_split_on_reset(tmp_path, waved):
    jitter = dict(waved)
    t = waved["t"].copy()
    t[1500] -= 0.5 * (t[1] - t[0]) + (t[1500] - t[1499])  # half a step before the row above
    jitter["t"] = t
    x = ("-o", tmp_path / "x.json", "--force")
    run("calibrate", _csv(tmp_path / "j.csv", jitter), "--poses", "continuous", *x, "--quiet")
    reset = dict(waved)
    reset["t"] = np.where(np.arange(len(t)) >= 1500, waved["t"] - 14.0, waved["t"])
    log = _csv(tmp_path / "r.csv", reset)
    user_error("calibrate", log, "--poses", "continuous", *x, match="pass --split-on-reset")
    run("calibrate", log, "--poses", "continuous", "--split-on-reset", *x, "--quiet")


def test_poses_none_lists_every_mode():
    import fieldcal

    with pytest.raises(fieldcal.InputError, match=r"'auto', 'still', .*'continuous'"):
        fieldcal.calibrate_log({"ax": [1.0], "ay": [0.0], "az": [0.0]}, poses=None)
