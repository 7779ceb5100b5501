"""Every command through click's CliRunner, and a one-line error with exit code 2 for bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

import fieldcal
from fieldcal.cli import cli
from fieldcal.geometry.rotations import exp_so3


def run(*args, ok=True):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    if ok:
        assert result.exit_code == 0, (result.output, result.exception)
    return result


def user_error(*args, match):
    """Exit code 2, one line on stderr starting with 'Error:', matching, no traceback."""
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 2, (result.output, result.exception)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    assert match in lines[0], lines[0]
    assert "Traceback" not in result.output
    return lines[0]


def _pose_csv(path, accel, mag=None, labels=None):
    counts = [len(a) for a in accel]
    labels = labels if labels is not None else np.repeat(np.arange(len(accel)), counts)
    cols = [labels, np.concatenate(accel)]
    header = "pose,ax,ay,az"
    if mag is not None:
        cols.append(np.concatenate(mag))
        header += ",mx,my,mz"
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=header, comments="", fmt="%.10g")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli")
    session = folder / "session.csv"
    run("simulate", "--seed", 4, "-o", session, "--truth", folder / "truth.json")
    cal = folder / "cal.json"
    result = run("calibrate", session, "-o", cal, "--gravity", 9.80665)
    return {"folder": folder, "session": session, "cal": cal, "summary": result.output}


def test_version_and_help():
    assert fieldcal.__version__ in run("--version").output
    for command in ("calibrate", "apply", "export", "simulate", "report", "demo"):
        assert "Usage: " in run(command, "--help").output


def test_calibrate_summary_and_json(files):
    out = files["summary"]
    for text in (
        "columns used: accel = ax,ay,az; mag = mx,my,mz; pose = pose",
        "15 poses grouped by the pose column",
        "accelerometer",
        "magnetometer",
        "dip angle",
        "misalignment",
        "fit certificate",
        "residual cost J",
        "within-pose scatter",
    ):
        assert text in out
    doc = json.loads(files["cal"].read_text())
    cal = fieldcal.Calibration.from_json(files["cal"].read_text())
    truth = fieldcal.Calibration.from_json((files["folder"] / "truth.json").read_text())
    assert cal.gravity_norm == pytest.approx(9.80665)
    assert abs(cal.dip_deg - truth.dip_deg) < 1.0
    assert len(doc["poses"]) == 15
    first = doc["poses"][0]
    assert {"label", "start", "stop", "samples", "share"} <= set(first)
    assert first["label"] == "0" and first["start"] == 0 and first["stop"] == first["samples"]


def test_calibrate_json_and_quiet(files, tmp_path):
    out = run("calibrate", files["session"], "-o", tmp_path / "c.json", "--json").output
    assert json.loads(out)["schema"] == "fieldcal.calibration"
    assert run("calibrate", files["session"], "-o", tmp_path / "c.json", "--quiet").output == ""


def test_calibrate_continuous_log_detects_poses(tmp_path):
    log = tmp_path / "log.csv"
    run("simulate", "--continuous", "--handheld", "--seed", 2, "--poses", 10, "-o", log)
    out = run("calibrate", log, "-o", tmp_path / "c.json").output
    assert "10 poses found by still detection at 100 Hz" in out
    assert "still detection: 10 segments" in out
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["still_detection"]["count"] == 10
    assert all(p["stop"] > p["start"] and p["std"] > 0 for p in doc["poses"])


def test_user_noise_and_residual_noise(tmp_path):
    session = fieldcal.simulate("paper", seed=6, n_poses=20)
    path = _pose_csv(tmp_path / "s.csv", session.accel, session.mag)
    std = {s: np.sqrt(np.trace(getattr(session.truth, s).noise_cov) / 3) for s in ("accel", "mag")}
    noise = f"accel={std['accel']:.4g},mag={std['mag']:.4g}"
    run("calibrate", path, "-o", tmp_path / "u.json", "--noise", noise)
    doc = json.loads((tmp_path / "u.json").read_text())
    assert doc["accel"]["noise_source"] == doc["mag"]["noise_source"] == "user"
    # one averaged reading per pose (as sap6 stores): noise from the residuals
    means = _pose_csv(
        tmp_path / "m.csv",
        [a.mean(0, keepdims=True) for a in session.accel],
        [m.mean(0, keepdims=True) for m in session.mag],
    )
    out = run("calibrate", means, "-o", tmp_path / "r.json").output
    assert "estimated from the fit's residuals" in out
    assert json.loads((tmp_path / "r.json").read_text())["mag"]["noise_source"] == "residuals"


def test_apply(files, tmp_path):
    out = tmp_path / "calibrated.csv"
    run("apply", files["cal"], files["session"], "-o", out)
    data = np.genfromtxt(out, delimiter=",", names=True)
    cal = fieldcal.Calibration.from_json(files["cal"].read_text())
    raw = np.column_stack([data["mx"], data["my"], data["mz"]])
    got = np.column_stack([data["mx_cal"], data["my_cal"], data["mz_cal"]])
    assert np.allclose(got, cal.correct_mag(raw), rtol=1e-7, atol=1e-8)
    assert np.allclose(np.linalg.norm(got, axis=1).mean(), 1.0, atol=0.02)


@pytest.mark.parametrize(
    ("fmt", "text"),
    [
        ("c-header", "FIELDCAL_ACCEL_MATRIX"),
        ("matlab", "C = (D - b) * A"),
        ("magneto", "A^-1"),
        ("json", '"schema"'),
    ],
)
def test_export(files, fmt, text, tmp_path):
    assert text in run("export", files["cal"], "--format", fmt).output
    run("export", files["cal"], "--format", fmt, "-o", tmp_path / "x")
    assert text in (tmp_path / "x").read_text()


def test_report(files, tmp_path):
    pytest.importorskip("matplotlib")
    html = tmp_path / "r.html"
    run("report", files["cal"], files["session"], "-o", html, "--png", tmp_path / "png")
    page = html.read_text()
    assert page.count("data:image/png;base64,") >= 4 and "<script" not in page
    assert {p.name for p in (tmp_path / "png").iterdir()} >= {"coverage.png", "histograms.png"}


def test_demo(tmp_path):
    out = run("demo", "--out", tmp_path, "--no-report").output
    assert "truth vs estimate" in out and "δ (accel, Eq. 19) =" in out and "δ (mag" in out
    assert "15 poses found by still detection" in out


def test_demo_without_matplotlib(tmp_path, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_matplotlib(name, *args, **kwargs):
        if name.startswith("matplotlib"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    out = run("demo", "--out", tmp_path).output
    assert "skipped the report" in out and not (tmp_path / "report.html").exists()


# ----------------------------------------------------------------------------- bad input
def test_missing_file(tmp_path):
    user_error("calibrate", tmp_path / "nope.csv", match="no such file")
    user_error("export", tmp_path / "nope.json", match="no such calibration file")


def test_unreadable_file(tmp_path):
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00\x81binary")
    user_error("calibrate", tmp_path / "bin.csv", match="not a text file")
    user_error("calibrate", tmp_path, match="is a folder")
    (tmp_path / "bad.json").write_text("{not json")
    user_error("export", tmp_path / "bad.json", match="not a fieldcal calibration")


def test_no_recognisable_columns(tmp_path):
    (tmp_path / "log.csv").write_text("foo,bar,baz\n1,2,3\n")
    user_error("calibrate", tmp_path / "log.csv", match="foo, bar, baz")


def test_non_numeric(tmp_path):
    (tmp_path / "log.csv").write_text("ax,ay,az\n1,2,3\n1,two,3\n")
    user_error("calibrate", tmp_path / "log.csv", match="non-numeric value 'two'")


def test_nan_rows(tmp_path, files):
    text = files["session"].read_text().splitlines()
    text[5] = "0,nan,1,2,3,4,5"
    text[9] = "0,inf,1,2,3,4,5"
    (tmp_path / "log.csv").write_text("\n".join(text) + "\n")
    user_error("calibrate", tmp_path / "log.csv", match="2 row(s) have NaN")
    run("calibrate", tmp_path / "log.csv", "--drop-nan", "-o", tmp_path / "c.json")


def test_too_few_poses(tmp_path):
    session = fieldcal.simulate("paper", seed=1, n_poses=5)
    path = _pose_csv(tmp_path / "s.csv", session.accel, session.mag)
    user_error("calibrate", path, "-o", tmp_path / "c.json", match="needs at least 8")


def test_no_still_interval(tmp_path):
    log = tmp_path / "log.csv"
    run("simulate", "--continuous", "--seed", 2, "--poses", 8, "-o", log)
    line = user_error("calibrate", log, "--still-threshold", "1e-9", match="no still interval")
    assert "--still-threshold" in line


def test_degenerate_poses(tmp_path):
    rng = np.random.default_rng(0)
    # ten poses turned about the body x axis only: gravity sweeps one plane of the sensor
    R = exp_so3(np.outer(np.linspace(0, 2 * np.pi, 10, endpoint=False), [1, 0, 0]))
    accel = [np.einsum("ij,j->i", r, [0, 0, -1]) + rng.normal(0, 1e-3, (50, 3)) for r in R]
    mag = [np.einsum("ij,j->i", r, [0.4, 0, 0.9]) + rng.normal(0, 1e-3, (50, 3)) for r in R]
    path = _pose_csv(tmp_path / "s.csv", accel, mag)
    user_error("calibrate", path, match="tilted up and down")


def test_bad_options(files, tmp_path):
    user_error("calibrate", files["session"], "--noise", "lots", match="--noise")
    user_error("calibrate", files["session"], "--mag-axes", "+x+x+z", match="axis map")
    user_error("calibrate", files["session"], "--accel-cols", "a,b", match="three column names")
    user_error("calibrate", files["session"], "--rate", "-5", "--pose-col", "ax", match="--rate")


def test_report_errors(files, tmp_path, monkeypatch):
    short = tmp_path / "short.csv"
    short.write_text("\n".join(files["session"].read_text().splitlines()[:100]) + "\n")
    user_error("report", files["cal"], short, "-o", tmp_path / "r.html", match="give the log it")
    import builtins

    real_import = builtins.__import__

    def no_matplotlib(name, *args, **kwargs):
        if name.startswith("matplotlib"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    user_error("report", files["cal"], files["session"], match="fieldcal[plot]")


def test_mirrored_magnetometer_is_declared_by_flag_or_axis_map(tmp_path):
    # a magnetometer whose z axis is mirrored relative to the accelerometer's (det < 0)
    session = fieldcal.simulate("paper", seed=8, mag_axes=np.diag([1.0, 1.0, -1.0]))
    path = _pose_csv(tmp_path / "s.csv", session.accel, session.mag)
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
