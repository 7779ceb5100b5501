"""poses="continuous" and poses="auto" in the log pipeline: which path runs, the note saying
why, the JSON record, the errors for logs the continuous estimator cannot take; the shared
trust path, the report and ``capture --poses continuous`` on a continuous calibration."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest
from click.testing import CliRunner

import fieldcal
from fieldcal.capture.feeds import Line
from fieldcal.capture.live_session import CaptureOptions, CaptureSession
from fieldcal.cli import cli
from fieldcal.errors import InputError
from fieldcal.logs import load_log
from fieldcal.output.report import FIGURES, report_figures, write_report
from fieldcal.pipeline import LogSettings, read_log, run_log
from fieldcal.simulation.continuous import simulate_continuous
from fieldcal.simulation.handwave import simulate_handwave


@pytest.fixture(scope="module")
def handwave_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("handwave") / "wave.csv"
    log = simulate_handwave(seed=8, seconds=30.0)
    log.write_csv(str(path))
    return path, log


def test_auto_picks_continuous_without_rests(handwave_csv):
    path, log = handwave_csv
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the detector's "rests move" warning is consumed
        run = run_log(read_log(path), LogSettings.of(gravity=9.80665))
    cal = run.calibration
    assert cal.method == "continuous"
    assert any("poses='auto': calibrated from continuous motion" in n for n in run.notes)
    doc = run.document()
    assert doc["continuous"]["source"] == "continuous"
    assert doc["continuous"]["trajectory"]["epochs"] == log.n
    assert {"motion", "downweighted"} <= set(doc["continuous"])
    again = fieldcal.Calibration.from_json(json.dumps(doc))
    assert again.options["mode"] == "continuous"
    assert again.gyro is not None
    # |g| folded back: the accelerometer's gain is near the identity in m/s² per m/s²
    sd = cal.covariance.stds([f"accel.gain[{i},{i}]" for i in range(3)])
    truth = np.asarray(log.truth.accel.gain) / 9.80665
    assert np.all(np.abs(np.diag(cal.accel.gain) - np.diag(truth)) < 5 * sd)


def test_auto_keeps_still_detection_for_logs_with_rests(tmp_path):
    sim = simulate_continuous("paper", seed=3)
    path = tmp_path / "rests.csv"
    sim.write_csv(str(path))
    run = run_log(read_log(path))
    assert run.calibration.method == "mle"
    assert any("rests found by still detection" in n for n in run.notes)
    assert run.poses.source == "still"


def test_continuous_axis_map_and_sign_fold_back(handwave_csv):
    path, _ = handwave_csv
    plain = run_log(read_log(path), LogSettings.of(poses="continuous")).calibration
    log = read_log(path)
    flipped = dataclasses.replace(log, accel=-log.accel)
    folded = run_log(flipped, LogSettings.of(poses="continuous", accel_sign="gravity")).calibration
    # the same fit on negated readings, folded back: the same numbers for the raw columns
    sd = plain.accel.bias_std
    assert np.all(np.abs(folded.accel.bias - (-plain.accel.bias)) < 0.05 * sd)
    assert np.allclose(folded.accel.gain, -plain.accel.gain, atol=0.05 * plain.accel.gain_std.max())
    assert folded.options["accel_sign"] == "gravity"


def test_continuous_needs_a_gyroscope_and_time(tmp_path):
    sim = simulate_handwave(seed=1, seconds=10.0)
    cols = {k: v for k, v in sim.columns.items() if not k.startswith("g")}
    path = tmp_path / "nogyro.csv"
    data = np.column_stack(list(cols.values()))
    np.savetxt(path, data, delimiter=",", header=",".join(cols), comments="")
    with pytest.raises(InputError, match="gyroscope"):
        run_log(read_log(path), LogSettings.of(poses="continuous"))
    with pytest.raises(InputError, match=r"poses \(--poses\) must be one of"):
        run_log(read_log(path), LogSettings.of(poses="tumbling"))


def test_demo_continuous_and_calibrate_poses_continuous(tmp_path):
    runner = CliRunner()
    out = tmp_path / "demo"
    result = runner.invoke(cli, ["demo", "--continuous", "--no-report", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "gyroscope: gain error" in result.output
    doc = json.loads((out / "cal.json").read_text())
    assert doc["method"] == "continuous" and doc["continuous"]["source"] == "continuous"
    # the same log through `calibrate --poses continuous`
    result = runner.invoke(
        cli,
        [
            "calibrate",
            str(out / "session.csv"),
            "-o",
            str(tmp_path / "c.json"),
            "--poses",
            "continuous",
        ],
    )
    assert result.exit_code in (0, 3), result.output
    assert json.loads((tmp_path / "c.json").read_text())["options"]["mode"] == "continuous"
    bad = runner.invoke(cli, ["calibrate", str(out / "session.csv"), "--poses", "tumble"])
    assert bad.exit_code == 2


def _svd_scale(gain):
    return float(np.exp(np.mean(np.log(np.linalg.svd(np.asarray(gain))[1]))))


@pytest.fixture(scope="module")
def wave_log(handwave_csv):
    path, log = handwave_csv
    return read_log(path), log


def _continuous(wave_log, **options):
    log, _ = wave_log
    return run_log(log, LogSettings.of(poses="continuous", gravity=9.80665, **options))


def test_continuous_world_magnetic_model_decides_and_checks(wave_log):
    """The shared trust path (issue 23 item 2): with --location the World Magnetic Model's dip
    decides the handedness (trust.handedness.decide) and the reference_* rules judge the dip.
    The simulated field dips −72.5° (in fieldcal's gauge, unmirrored): Hobart (WMM −72.6°)
    agrees; at 60° N, 10° E (+73.0°) the magnetometer must be mirrored, which the verdict
    says. --field-strength wmm gives the magnetometer's gain in raw units per µT."""
    _, sim = wave_log
    run = _continuous(wave_log, location="-42.9,147.3", field_strength="wmm")
    cal = run.calibration
    assert cal.options["mag_handedness"] == "reference" and cal.options["mag_mirrored"] is False
    assert cal.field_reference is not None
    assert not any(r.code.startswith("reference_") for r in cal.verdict.reasons)
    assert "negative_dip" not in cal.verdict.codes  # the reference settled its sign
    assert not any("not used" in n for n in run.notes)
    expected = sim.field_strength / cal.field_reference.intensity_in("uT")  # raw per µT
    scale = _svd_scale(cal.mag.gain)
    sd = float(np.max(cal.mag.gain_std))
    assert abs(scale - expected) < 5 * sd + 0.02 * expected
    north = _continuous(wave_log, location="60,10").calibration
    assert "reference_mirrored" in north.verdict.codes and north.verdict.level == "warn"
    assert north.options["mag_mirrored"] is True
    assert np.linalg.det(north.accel.gain) * np.linalg.det(north.mag.gain) < 0
    assert north.dip_deg == pytest.approx(-cal.dip_deg, abs=1e-6)


def test_continuous_mag_mirrored_and_targets(wave_log):
    plain = _continuous(wave_log).calibration
    assert plain.options["mag_mirrored"] is False and plain.options["mag_handedness"] == "stated"
    assert "negative_dip" in plain.verdict.codes  # the generic rule, on the continuous result
    assert plain.accuracy is not None and plain.accuracy.heading_deg < 2.0
    mirrored = _continuous(wave_log, mag_mirrored=True).calibration
    assert mirrored.options["mag_mirrored"] is True
    assert np.allclose(mirrored.mag.gain, -plain.mag.gain)
    assert mirrored.dip_deg == pytest.approx(-plain.dip_deg, abs=1e-6)
    assert "negative_dip" not in mirrored.verdict.codes
    # the accuracy rules against the targets: a heading target far below what the log gives
    strict = _continuous(wave_log, target_heading=plain.accuracy.heading_deg / 10).calibration
    assert "unusable" in strict.verdict.codes and strict.verdict.level == "fail"
    loose = _continuous(wave_log, target_heading=10 * plain.accuracy.heading_deg).calibration
    assert not {"unusable", "accuracy"} & set(loose.verdict.codes)


def test_report_of_a_continuous_calibration(handwave_csv, tmp_path):
    """The report (issue 23 item 5): the trajectory and coverage figure and the residuals over
    time take the place of the pose figures, and the page does not call the file old for
    having no per-pose residuals."""
    pytest.importorskip("matplotlib", reason="matplotlib (the plot extra) not installed")
    path, _ = handwave_csv
    cal = run_log(read_log(path), LogSettings.of(poses="continuous")).calibration
    assert {"trajectory", "motion_residuals"} <= set(FIGURES)
    figures = report_figures(cal, load_log(str(path)))
    assert {"trajectory", "motion_residuals", "timeline"} <= set(figures)
    assert not {"residuals", "coverage"} & set(figures)
    # the turns drawn are the calibration's own totals
    legend = [t.get_text() for t in figures["trajectory"].axes[-1].get_legend().get_texts()]
    turned = cal.options["trajectory"]["turned_deg"]
    for axis, text in zip("xyz", legend, strict=True):
        assert float(text.split(": ")[1].rstrip("°")) == pytest.approx(turned[axis], rel=0.02)
    out = tmp_path / "report.html"
    write_report(cal, load_log(str(path)), out)
    page = out.read_text()
    assert "Trajectory and coverage" in page and "Residuals over time" in page
    assert "no per-pose residuals" not in page


def test_capture_poses_continuous_shows_coverage_and_stops_on_pass(handwave_csv, tmp_path):
    """``capture --poses continuous`` (issue 23 item 5): the rotations covered so far, what the
    motion still lacks, a running calibration from the whole log as it grows, and the stop on
    ``--until pass``; the final calibration is the continuous estimator's on every sample."""
    path, _ = handwave_csv
    lines = path.read_text().splitlines()
    events: list = []
    settings = LogSettings.of(poses="continuous", gravity=9.80665)
    options = CaptureOptions(settings=settings, until="pass")
    session = CaptureSession(options, tmp_path / "cap", events.append)
    session.receive(Line(0.0, lines[0]))
    chunk = 500  # 5 s at 100 Hz
    for start in range(1, len(lines), chunk):
        for k, text in enumerate(lines[start : start + chunk], start):
            session.receive(Line(k / 100.0, text))
        session.step(force=True)
        if session.done:
            break
    assert session.motion is not None and "motion so far" in session.message
    assert session.motion["gravity_coverage"] > 0.5
    assert any(e.kind == "next" for e in events)
    fits = [e for e in events if e.kind == "calibration"]
    assert fits and all("s of continuous motion" in e.text for e in fits)
    assert session.done, [e.text for e in fits]  # the verdict passed and the targets were met
    assert "PASS" in fits[-1].text
    result = session.finish("the verdict is pass and the targets are met")
    assert result.calibration is not None and result.calibration.method == "continuous"
    assert (tmp_path / "cap" / "cal.json").is_file()
    bad = CliRunner().invoke(cli, ["capture", "--from", str(path), "--poses", "windows"])
    assert bad.exit_code == 2 and "--poses continuous" in bad.output
