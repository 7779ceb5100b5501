"""The shared options: choices from the registries, values checked when parsed (one line
naming the option), noise and pose-noise specifications, the magnetometer's handedness."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _cli import pose_csv, run, user_error

import fieldcal
from fieldcal.cli import cli
from fieldcal.methods import METHODS
from fieldcal.output.exports import FORMATS
from fieldcal.simulation.continuous import simulate_continuous


def test_choices_come_from_the_registries():
    params = {c: {p.name: p for p in cli.commands[c].params} for c in ("calibrate", "export")}
    assert list(params["calibrate"]["method"].type.choices) == list(METHODS)
    assert params["calibrate"]["method"].default == "mle"
    assert list(params["export"]["fmt"].type.choices) == list(FORMATS)
    # written out in the CLI (importing fieldcal.logs would slow --help), kept equal here
    from fieldcal.geometry.frames import ACCEL_SIGNS
    from fieldcal.pipeline import POSE_MODES

    assert list(params["calibrate"]["poses"].type.choices) == list(POSE_MODES)
    assert params["calibrate"]["poses"].default == POSE_MODES[0] == "auto"
    assert list(params["calibrate"]["accel_sign"].type.choices) == list(ACCEL_SIGNS)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("--gravity", "abc"), "'abc' is not a number"),
        (("--gravity", "0"), "--gravity"),
        (("--field-strength", "-48.5"), "out of range"),
        (("--window", "inf"), "not a finite number"),
        (("--min-still", "inf"), "--min-still"),
        (("--min-still", "nan"), "--min-still"),
        (("--still-trim", "-1"), "--still-trim"),
        (("--trim", "inf"), "--trim"),
        (("--rate", "0"), "--rate"),
        (("--still-threshold", "1e300"), "out of range"),
        (("--noise", "1e300"), "--noise"),
        (("--noise", "inf"), "--noise"),
        (("--noise", "accel=nan"), "--noise"),
        (("--pose-noise", "1e300"), "--pose-noise"),
        (("--method", "nope"), "--method"),
        (("--bogus",), "No such option"),
    ],
)
def test_usage_errors_are_one_line(files, args, match):
    line = user_error("calibrate", files["session"], *args, match=match)
    assert "Usage:" not in line and "Traceback" not in line


def test_the_old_trim_flag_is_taken_with_a_note(tmp_path):
    """--trim, the still detector's cut at each interval's ends, is now --still-trim (one word,
    one meaning): the old spelling gives the same calibration and says the new one."""
    log = tmp_path / "rests.csv"
    simulate_continuous("paper", seed=3).write_csv(str(log))
    old = run("calibrate", log, "--trim", "0.1", "--no-gyro", "-o", tmp_path / "old.json")
    assert "--trim is now --still-trim" in old.stderr
    new = run("calibrate", log, "--still-trim", "0.1", "--no-gyro", "-o", tmp_path / "new.json")
    assert "is now" not in new.stderr
    a, b = (json.loads((tmp_path / f).read_text()) for f in ("old.json", "new.json"))
    assert a["still_detection"] == b["still_detection"] and a["accel"] == b["accel"]


def test_bad_options(files, tmp_path):
    user_error("calibrate", files["session"], "--noise", "lots", match="--noise")
    user_error("calibrate", files["session"], "--mag-axes", "+x+x+z", match="axis map")
    user_error("calibrate", files["session"], "--accel-cols", "a,b", match="three column names")
    user_error("calibrate", files["session"], "--rate", "-5", "--pose-col", "ax", match="--rate")


def test_no_robust_and_pose_noise_options(disturbed, tmp_path):
    result = run("calibrate", disturbed, "--no-robust", "-o", tmp_path / "n.json", ok=False)
    doc = json.loads((tmp_path / "n.json").read_text())
    assert doc["rejected"] == [] and doc["options"]["robust"] is False
    assert doc["options"]["trim"] is False
    assert result.exit_code == (3 if doc["verdict"]["level"] == "fail" else 0)
    run("calibrate", disturbed, "--pose-noise", "accel=0.001,mag=0.002", "-o", tmp_path / "q.json")
    doc = json.loads((tmp_path / "q.json").read_text())
    assert doc["accel"]["pose_noise_std"] == 0.001 and doc["mag"]["pose_noise_std"] == 0.002
    result = run(
        "calibrate", disturbed, "--pose-noise", "none", "-o", tmp_path / "z.json", ok=False
    )
    doc = json.loads((tmp_path / "z.json").read_text())
    assert result.exit_code == (3 if doc["verdict"]["level"] == "fail" else 0)
    assert doc["accel"]["pose_noise_std"] == doc["mag"]["pose_noise_std"] == 0.0
    for bad in ("lots", "-1", "gyro=0.1", "accel=0.1,mag=x"):
        user_error("calibrate", disturbed, "--pose-noise", bad, match="--pose-noise")


def test_user_noise_and_residual_noise(tmp_path):
    session = fieldcal.simulate("paper", seed=6, n_poses=20)
    path = pose_csv(tmp_path / "s.csv", session.accel, session.mag)
    std = {s: np.sqrt(np.trace(getattr(session.truth, s).noise_cov) / 3) for s in ("accel", "mag")}
    noise = f"accel={std['accel']:.4g},mag={std['mag']:.4g}"
    run("calibrate", path, "-o", tmp_path / "u.json", "--noise", noise)
    doc = json.loads((tmp_path / "u.json").read_text())
    assert doc["accel"]["noise_source"] == doc["mag"]["noise_source"] == "user"
    # one averaged reading per pose (as sap6 stores): noise from the residuals
    means = pose_csv(
        tmp_path / "m.csv",
        [a.mean(0, keepdims=True) for a in session.accel],
        [m.mean(0, keepdims=True) for m in session.mag],
    )
    out = run("calibrate", means, "-o", tmp_path / "r.json").output
    assert "estimated from the fit's residuals" in out
    assert json.loads((tmp_path / "r.json").read_text())["mag"]["noise_source"] == "residuals"


def test_mirrored_magnetometer_is_declared_by_flag_or_axis_map(tmp_path):
    # a magnetometer whose z axis is mirrored relative to the accelerometer's (det < 0)
    session = fieldcal.simulate("paper", seed=8, mag_axes=np.diag([1.0, 1.0, -1.0]))
    path = pose_csv(tmp_path / "s.csv", session.accel, session.mag)
    truth = session.truth.dip_deg
    run("calibrate", path, "-o", tmp_path / "a.json")
    # undeclared, the data cannot tell its handedness: the right-handed twin, dip sign flipped
    a = fieldcal.Calibration.from_json((tmp_path / "a.json").read_text())
    assert abs(a.dip_deg + truth) < 1.0 and np.linalg.det(a.mag.gain) > 0
    run("calibrate", path, "--mag-mirrored", "-o", tmp_path / "m.json")
    m = fieldcal.Calibration.from_json((tmp_path / "m.json").read_text())
    assert abs(m.dip_deg - truth) < 1.0 and np.linalg.det(m.mag.gain) < 0
    out = run("calibrate", path, "--mag-axes", "+x+y-z", "-o", tmp_path / "b.json").output
    assert "folded back" in out
    b = fieldcal.Calibration.from_json((tmp_path / "b.json").read_text())
    assert abs(b.dip_deg - truth) < 1.0
    # the folded calibration applies to the raw columns: |m| = 1 and the true dip per pose
    raw_a = np.array([x.mean(0) for x in session.accel])
    raw_m = np.array([x.mean(0) for x in session.mag])
    va, vm = b.correct_accel(raw_a), b.correct_mag(raw_m)
    assert np.allclose(np.linalg.norm(vm, axis=1), 1.0, atol=0.02)
    cos = np.sum(va * vm, 1) / np.linalg.norm(va, axis=1) / np.linalg.norm(vm, axis=1)
    assert np.allclose(np.degrees(np.arcsin(-cos)), truth, atol=1.0)


def _codes(path):
    return [r["code"] for r in json.loads(path.read_text())["verdict"]["reasons"]]


def test_target_options_reach_the_verdict(files, tmp_path):
    """--target-tilt on calibrate and batch (and a manifest's target_tilt column) is the
    verdict's tilt target: half the predicted tilt error warns (code accuracy, exit 0), a
    fifth of it fails (unusable, exit 3, the files written); unset, fieldcal.Targets'."""
    tilt = json.loads(files["cal"].read_text())["accuracy"]["tilt_deg"]
    assert "accuracy" not in _codes(files["cal"])  # the default targets are met
    half, tight = tmp_path / "half.json", tmp_path / "tight.json"
    run("calibrate", files["session"], "--target-tilt", tilt / 2, "-o", half)
    assert "accuracy" in _codes(half) and "unusable" not in _codes(half)
    result = run("calibrate", files["session"], "--target-tilt", tilt / 10, "-o", tight, ok=False)
    assert result.exit_code == 3 and "unusable" in _codes(tight)
    user_error("calibrate", files["session"], "--target-norm", "0", match="--target-norm")
    # batch: the command's target for every log, a manifest cell overriding it for its log
    logs = {d: tmp_path / f"{d}.csv" for d in ("strict", "loose")}
    for path in logs.values():
        path.write_bytes(files["session"].read_bytes())
    manifest = tmp_path / "logs.csv"
    manifest.write_text(
        f"log,device,target_tilt\n{logs['strict']},strict,\n{logs['loose']},loose,1e3\n"
    )
    out = tmp_path / "out"
    run("batch", manifest, "--out", out, "--jobs", 1, "--target-tilt", tilt / 2, "-q")
    assert "accuracy" in _codes(out / "strict" / "cal.json")
    assert "accuracy" not in _codes(out / "loose" / "cal.json")
