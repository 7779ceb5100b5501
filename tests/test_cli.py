"""Every command through click's CliRunner: the verdict first, exit code 3 on a fail verdict
(files still written), and a one-line error with exit code 2 for bad input."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import fieldcal
from fieldcal.cli import EXIT_FAIL, cli
from fieldcal.geometry.rotations import exp_so3
from fieldcal.methods import METHODS
from fieldcal.output.exports import FORMATS
from fieldcal.output.summary import MAX_POSE_ROWS


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
    """A log with a pose column; ``accel`` or ``mag`` may be None for a one-sensor log."""
    first = accel if accel is not None else mag
    counts = [len(a) for a in first]
    labels = labels if labels is not None else np.repeat(np.arange(len(first)), counts)
    cols, header = [labels], "pose"
    if accel is not None:
        cols.append(np.concatenate(accel))
        header += ",ax,ay,az"
    if mag is not None:
        cols.append(np.concatenate(mag))
        header += ",mx,my,mz"
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=header, comments="", fmt="%.10g")
    return path


def _lines(text):
    return text.splitlines()


@pytest.fixture(scope="module")
def disturbed(tmp_path_factory):
    """20 poses whose pose 3 has a magnetometer offset of 30 % of the field (iron nearby)."""
    session = fieldcal.simulate("paper", seed=4, n_poses=20)
    mag = [m.copy() for m in session.mag]
    mag[3] += np.array([0.3, 0.0, 0.0]) * np.abs(mag[3]).max()
    return _pose_csv(tmp_path_factory.mktemp("disturbed") / "s.csv", session.accel, mag)


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


def test_version_and_help_load_no_heavy_module():
    # --version and --help import numpy, click and fieldcal's light modules only
    code = (
        "import sys\n"
        "from fieldcal.cli import cli\n"
        "for args in (['--version'], ['--help'], ['calibrate', '--help']):\n"
        "    try:\n"
        "        cli(args, prog_name='fieldcal')\n"
        "    except SystemExit:\n"
        "        pass\n"
        "heavy = ('rich', 'scipy', 'matplotlib', 'fieldcal.pipeline', 'fieldcal.trust')\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy or m in heavy))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_choices_come_from_the_registries():
    params = {c: {p.name: p for p in cli.commands[c].params} for c in ("calibrate", "export")}
    assert list(params["calibrate"]["method"].type.choices) == list(METHODS)
    assert params["calibrate"]["method"].default == "mle"
    assert list(params["export"]["fmt"].type.choices) == list(FORMATS)
    # written out in the CLI (importing fieldcal.logs would slow --help), kept equal here
    from fieldcal.geometry.frames import ACCEL_SIGNS
    from fieldcal.logs.poses import POSE_SOURCES

    assert list(params["calibrate"]["poses"].type.choices) == list(POSE_SOURCES)
    assert params["calibrate"]["poses"].default == POSE_SOURCES[0]
    assert list(params["calibrate"]["accel_sign"].type.choices) == list(ACCEL_SIGNS)


def test_calibrate_summary_and_json(files):
    out = files["summary"]
    doc = json.loads(files["cal"].read_text())
    # the verdict first, then each reason on its own line
    verdict = doc["verdict"]
    assert verdict["level"] == "pass"
    lines = _lines(out)
    assert lines[0] == "verdict: PASS"
    assert lines[1 : 1 + len(verdict["reasons"])] == [f"  {r}" for r in verdict["reasons"]]
    for text in (
        "pose-level noise std per axis (raw units)",
        "predicted accuracy after calibration",
        "tilt ",
        "heading ",
        "|a| ",
        "|m| ",
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
    cal = fieldcal.Calibration.from_json(files["cal"].read_text())
    truth = fieldcal.Calibration.from_json((files["folder"] / "truth.json").read_text())
    assert doc["accuracy"]["tilt_deg"] > 0 and doc["rejected"] == []
    assert doc["accel"]["pose_noise_std"] >= 0 and doc["mag"]["pose_noise_std"] >= 0
    assert cal.gravity_norm == pytest.approx(9.80665)
    assert abs(cal.dip_deg - truth.dip_deg) < 1.0
    assert len(doc["poses"]) == 15
    first = doc["poses"][0]
    assert {"label", "start", "stop", "samples", "share"} <= set(first)
    assert first["label"] == "0" and first["start"] == 0 and first["stop"] == first["samples"]


def test_calibrate_json_and_quiet(files, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    # --json alone prints the document and writes nothing
    out = run("calibrate", files["session"], "--json").stdout
    assert json.loads(out)["schema"] == "fieldcal.calibration"
    assert list(tmp_path.iterdir()) == []
    # with -o it also writes the file, the same document
    out = run("calibrate", files["session"], "--json", "-o", "c.json").stdout
    assert json.loads(out)["verdict"] == json.loads((tmp_path / "c.json").read_text())["verdict"]
    assert run("calibrate", files["session"], "-o", "q.json", "--quiet").output == ""
    # without -o and --json: cal.json
    run("calibrate", files["session"], "--quiet")
    assert {p.name for p in tmp_path.iterdir()} == {"c.json", "q.json", "cal.json"}


def test_fail_verdict_exits_3_and_still_writes(files, tmp_path):
    # the magnetometer columns are a copy of the accelerometer's: the verdict must be fail
    session = fieldcal.simulate("paper", seed=4)
    path = _pose_csv(tmp_path / "copy.csv", session.accel, [a.copy() for a in session.accel])
    result = run("calibrate", path, "-o", tmp_path / "c.json", ok=False)
    assert result.exit_code == EXIT_FAIL == 3, (result.output, result.exception)
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["verdict"]["level"] == "fail"
    assert any("affine copy" in r for r in doc["verdict"]["reasons"])
    lines = _lines(result.stdout)
    assert lines[0] == "verdict: FAIL" and "affine copy" in lines[1]
    assert lines[-1] == f"wrote {tmp_path / 'c.json'}"
    # --json: the document on stdout, the verdict on stderr, exit code 3 all the same
    result = run("calibrate", path, "--json", "-o", tmp_path / "j.json", ok=False)
    assert result.exit_code == 3 and (tmp_path / "j.json").is_file()
    assert json.loads(result.stdout)["verdict"]["level"] == "fail"
    assert _lines(result.stderr)[0] == "verdict: FAIL"
    result = run("calibrate", path, "-q", "-o", tmp_path / "q.json", ok=False)
    assert result.exit_code == 3 and result.stdout == "" and (tmp_path / "q.json").is_file()
    assert "affine copy" in result.stderr


def test_rejected_poses_listed_with_reasons(disturbed, tmp_path):
    out = run("calibrate", disturbed, "-o", tmp_path / "r.json").output
    doc = json.loads((tmp_path / "r.json").read_text())
    assert [(r["index"], r["sensor"]) for r in doc["rejected"]] == [(3, "mag")]
    assert doc["verdict"]["level"] == "warn" and _lines(out)[0] == "verdict: WARN"
    assert "rejected" in doc["poses"][3] and "rejected" not in doc["poses"][2]
    reason = doc["rejected"][0]["reason"]
    assert "rejected poses (1, left out of the fit):" in out
    assert f"  pose 3 (mag, p = {doc['rejected'][0]['p_value']:.2g}): {reason}" in out


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


def test_one_sensor_summary_has_no_dip(tmp_path):
    session = fieldcal.simulate("paper", seed=3)
    for name, accel, mag in (("a", session.accel, None), ("m", None, session.mag)):
        path = _pose_csv(tmp_path / f"{name}.csv", accel, mag)
        out = run("calibrate", path, "-o", tmp_path / f"{name}.json").output
        doc = json.loads((tmp_path / f"{name}.json").read_text())
        assert doc["dip_deg"] is None
        assert "dip angle" not in out and "heading" not in out and "misalignment" not in out
        assert ("tilt " in out) == (accel is not None) and ("|m| " in out) == (mag is not None)


def test_long_pose_table_is_cut(tmp_path):
    n = MAX_POSE_ROWS + 5
    session = fieldcal.simulate("paper", seed=5, n_poses=n)
    path = _pose_csv(tmp_path / "s.csv", session.accel, session.mag)
    out = run("calibrate", path, "-o", tmp_path / "c.json").output
    assert len(json.loads((tmp_path / "c.json").read_text())["poses"]) == n
    assert "… and 5 more poses" in out
    rows = [line.split()[0] for line in _lines(out) if line.strip()[:2].strip().isdigit()]
    assert str(MAX_POSE_ROWS - 1) in rows and str(MAX_POSE_ROWS) not in rows


def test_user_text_is_printed_literally(tmp_path):
    # column names, labels and paths that look like rich markup or emoji codes
    session = fieldcal.simulate("paper", seed=4)
    labels = np.repeat([f"[i]p{i}:smile:" for i in range(15)], [len(a) for a in session.accel])
    path = tmp_path / "m.csv"
    rows = np.column_stack([np.concatenate(session.accel), np.concatenate(session.mag)])
    with path.open("w") as f:
        f.write("pose,[bold]x,[bold]y,[bold]z,mx,my,mz\n")
        for label, row in zip(labels, rows, strict=True):
            f.write(label + "," + ",".join(f"{v:.10g}" for v in row) + "\n")
    output = tmp_path / "[red]c.json"
    out = run("calibrate", path, "--accel-cols", "[bold]x,[bold]y,[bold]z", "-o", output).output
    assert "accel = [bold]x,[bold]y,[bold]z" in out
    assert "[i]p0:smile:" in out and f"wrote {output}" in out and output.is_file()


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
    # without --format, the suffix of -o names the format
    out = tmp_path / f"cal{FORMATS[fmt].suffix}"
    run("export", files["cal"], "-o", out)
    assert text in out.read_text()


def test_export_default_format_and_bad_format(files):
    assert "FIELDCAL_ACCEL_MATRIX" in run("export", files["cal"]).output
    # a version 1 file (fieldcal 0.1) exports too
    v1 = Path(__file__).parent / "data" / "calibration-v0.1.json"
    assert "FIELDCAL_MAG_MATRIX" in run("export", v1, "--format", "c-header").output
    result = run("export", files["cal"], "--format", "excel", ok=False)
    assert result.exit_code == 2 and "c-header" in result.output


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
    # the clean simulated session passes; the verdict comes right after the simulation line
    assert _lines(out)[1] == "verdict: PASS"
    assert json.loads((tmp_path / "cal.json").read_text())["verdict"]["level"] == "pass"


def test_demo_without_matplotlib(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as if it were not installed
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


# ----------------------------------------------------------------------------- files (issue #10)
def _no_temporaries(folder):
    return [p.name for p in Path(folder).rglob("*") if p.name.endswith(".part")] == []


def test_an_output_is_never_an_input(files, tmp_path):
    """Compared by file identity: the path itself, a hard link and a symbolic link are refused,
    with or without --force, and the input is left as it was."""
    log, cal = tmp_path / "log.csv", tmp_path / "cal.json"
    log.write_bytes(files["session"].read_bytes())
    cal.write_bytes(files["cal"].read_bytes())
    before = {p: p.read_bytes() for p in (log, cal)}
    hard, soft = tmp_path / "hard.csv", tmp_path / "soft.csv"
    os.link(log, hard)
    soft.symlink_to(log)
    for args in (
        ("calibrate", log, "-o", log),
        ("calibrate", log, "-o", hard),
        ("calibrate", log, "-o", soft, "--force"),
        ("apply", cal, log, "-o", log, "--force"),
        ("apply", cal, log, "-o", hard, "--force"),
        ("apply", cal, log, "-o", soft),
        ("apply", cal, log, "-o", cal, "--force"),
        ("export", cal, "-o", cal, "--force"),
        ("report", cal, log, "-o", hard, "--force"),
    ):
        user_error(*args, match="input")
    # a figure of --png that would land on the log (a log may have any suffix)
    (tmp_path / "figs").mkdir()
    figure = tmp_path / "figs" / "timeline.png"
    figure.write_bytes(log.read_bytes())
    user_error(
        "report",
        cal,
        figure,
        "-o",
        tmp_path / "r.html",
        "--png",
        tmp_path / "figs",
        "--force",
        match="is the input log itself",
    )
    user_error("calibrate", log, "-o", hard, "--force", match="same file as the input log")
    assert {p: p.read_bytes() for p in (log, cal)} == before
    assert _no_temporaries(tmp_path)


def test_an_existing_output_needs_force(files, tmp_path):
    log, cal = files["session"], files["cal"]
    old = tmp_path / "old"
    old.write_text("keep me\n")
    pngs = tmp_path / "png"
    pngs.mkdir()
    (pngs / "coverage.png").write_text("keep me\n")
    demo_dir = tmp_path / "demo"
    demo_dir.mkdir()
    (demo_dir / "cal.json").write_text("keep me\n")
    for args in (
        ("calibrate", log, "-o", old),
        ("calibrate", log, "--json", "-o", old),
        ("apply", cal, log, "-o", old),
        ("export", cal, "-o", old),
        ("report", cal, log, "-o", old),
        ("report", cal, log, "-o", tmp_path / "new.html", "--png", pngs),
        ("simulate", "-o", old),
        ("simulate", "-o", tmp_path / "new.csv", "--truth", old),
        ("demo", "--out", demo_dir, "--no-report"),
    ):
        line = user_error(*args, match="exists; pass --force to replace it")
        assert line.startswith("Error: ") and line.endswith("exists; pass --force to replace it")
    assert old.read_text() == "keep me\n" and (demo_dir / "cal.json").read_text() == "keep me\n"
    assert not (tmp_path / "new.csv").exists() and not (tmp_path / "new.html").exists()
    # with --force each is replaced
    run("export", cal, "-o", old, "--format", "matlab", "--force")
    assert "A_accel" in old.read_text()
    run("calibrate", log, "-o", old, "--force", "-q")
    assert json.loads(old.read_text())["schema"] == "fieldcal.calibration"
    run("simulate", "-o", tmp_path / "new.csv", "--truth", old, "--force")
    assert json.loads(old.read_text())["method"] == "truth"
    assert _no_temporaries(tmp_path)


def test_outputs_are_checked_before_any_work(files, tmp_path):
    user_error("calibrate", files["session"], "-o", tmp_path / "nope" / "c.json", match="folder")
    user_error("calibrate", files["session"], "-o", tmp_path, match="is a folder")
    user_error("simulate", "-o", tmp_path / "a", "--truth", tmp_path / "a", match="given twice")
    # an output problem is reported before a bad log is even read
    user_error("calibrate", tmp_path / "missing.csv", "-o", files["cal"], match="--force")


def _interrupt_on(monkeypatch, target, name, after=0):
    """Make ``target.name`` raise KeyboardInterrupt on its call number ``after + 1``."""
    real = getattr(target, name)
    calls = []

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) > after:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(target, name, interrupted)


def test_interrupted_apply_leaves_the_old_output(files, tmp_path, monkeypatch):
    """Ctrl-C half-way through a streamed apply: exit 130, one line, the previous output intact
    and no temporary file left."""
    import fieldcal.logs.apply as apply_module

    out = tmp_path / "out.csv"
    out.write_text("the previous output\n")
    monkeypatch.setattr(apply_module, "CHUNK_ROWS", 100)
    _interrupt_on(monkeypatch, fieldcal.Calibration, "correct_mag", after=3)  # after 3 chunks
    result = run("apply", files["cal"], files["session"], "-o", out, "--force", ok=False)
    assert result.exit_code == 130
    assert result.stderr == "Interrupted; nothing was written\n"
    assert out.read_text() == "the previous output\n"
    assert _no_temporaries(tmp_path)


def test_interrupted_calibrate_and_simulate(files, tmp_path, monkeypatch):
    import fieldcal.pipeline

    old = tmp_path / "cal.json"
    old.write_text("{}\n")
    _interrupt_on(monkeypatch, fieldcal.pipeline, "run_log")
    result = run("calibrate", files["session"], "-o", old, "--force", ok=False)
    assert (result.exit_code, result.stderr) == (130, "Interrupted; nothing was written\n")
    assert old.read_text() == "{}\n"
    # interrupted after the first of two files: the message names the one completed
    _interrupt_on(monkeypatch, fieldcal.Calibration, "to_json")
    session, truth = tmp_path / "s.csv", tmp_path / "t.json"
    result = run("simulate", "-o", session, "--truth", truth, ok=False)
    assert result.exit_code == 130
    assert result.stderr == f"Interrupted; completed {session}; nothing else was written\n"
    assert session.is_file() and not truth.exists() and _no_temporaries(tmp_path)


def test_an_error_half_way_leaves_the_old_output(files, tmp_path):
    """A bad value deep in the log stops apply with one line; the old output stays whole."""
    lines = files["session"].read_text().splitlines()
    lines[-3] = "7,1,2,3,oops,5,6"
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out.csv"
    out.write_text("the previous output\n")
    user_error("apply", files["cal"], bad, "-o", out, "--force", match="'oops'")
    assert out.read_text() == "the previous output\n" and _no_temporaries(tmp_path)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("--gravity", "abc"), "'abc' is not a number"),
        (("--gravity", "0"), "--gravity"),
        (("--field-strength", "-48.5"), "out of range"),
        (("--window", "inf"), "not a finite number"),
        (("--min-still", "inf"), "--min-still"),
        (("--min-still", "nan"), "--min-still"),
        (("--trim", "-1"), "--trim"),
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


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("calibrat",), "No such command 'calibrat'"),
        (("calibrate",), "Missing argument 'LOG'"),
        (("--bogus",), "No such option"),
        (("simulate", "--poses", "0"), "--poses"),
        (("simulate", "--seed", "-1"), "--seed"),
        (("simulate", "--rate", "nan"), "--rate"),
        (("simulate", "--preset", "nope"), "--preset"),
        (("demo", "--seed", "x"), "--seed"),
        (("export",), "Missing argument"),
        (("apply", "a.json", "b.csv"), "Missing option '-o'"),
    ],
)
def test_command_usage_errors_are_one_line(args, match):
    user_error(*args, match=match)


def test_unexpected_errors_are_one_line_bugs(files, monkeypatch):
    import fieldcal.pipeline

    def broken(*args, **kwargs):
        raise KeyError("oops")

    monkeypatch.setattr(fieldcal.pipeline, "run_log", broken)
    result = run("calibrate", files["session"], "--json", ok=False)
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: KeyError: 'oops'; this is a bug")
    assert "FIELDCAL_DEBUG=1" in lines[0] and "Traceback" not in result.output
    # FIELDCAL_DEBUG=1 lets the traceback through
    monkeypatch.setenv("FIELDCAL_DEBUG", "1")
    result = run("calibrate", files["session"], "--json", ok=False)
    assert isinstance(result.exception, KeyError)


def test_runtime_warnings_never_reach_the_terminal(files, tmp_path, monkeypatch):
    import warnings

    import fieldcal.pipeline

    real = fieldcal.pipeline.run_log

    def noisy(*args, **kwargs):
        with np.errstate(all="warn"):
            np.float64(1.0) / np.float64(0.0)  # numpy's RuntimeWarning: divide by zero
        warnings.warn("a note meant for the user", UserWarning, stacklevel=1)
        return real(*args, **kwargs)

    monkeypatch.setattr(fieldcal.pipeline, "run_log", noisy)
    result = run("calibrate", files["session"], "-o", tmp_path / "c.json")
    assert "divide by zero" not in result.output and "RuntimeWarning" not in result.output
    assert "warning: a note meant for the user" in result.stdout


def test_progress_reaches_the_display(disturbed, files, tmp_path, monkeypatch):
    """calibrate passes the library's progress lines (the robust fit's drops) to the status
    line, apply its rows; the status line itself is off when stderr is not a terminal."""
    import contextlib

    import fieldcal.cli
    import fieldcal.logs.apply as apply_module

    seen = []

    @contextlib.contextmanager
    def recorder(quiet):
        yield None if quiet else seen.append

    monkeypatch.setattr(fieldcal.cli, "_progress", recorder)
    run("calibrate", disturbed, "-o", tmp_path / "c.json")
    assert "dropped pose 3 (mag)" in seen and any(s.startswith("calibrating") for s in seen)
    seen.clear()
    monkeypatch.setattr(apply_module, "CHUNK_ROWS", 200)
    monkeypatch.setattr(apply_module, "PROGRESS_SECONDS", 0.0)
    run("apply", files["cal"], files["session"], "-o", tmp_path / "a.csv")
    assert "apply: 200 rows" in " ".join(seen)
    seen.clear()
    run("apply", files["cal"], files["session"], "-o", tmp_path / "b.csv", "-q")
    assert seen == []
    # under CliRunner stderr is not a terminal: no status line, nothing on stderr
    monkeypatch.undo()
    assert run("calibrate", files["session"], "-o", tmp_path / "d.json").stderr == ""


def test_apply_keeps_the_format_of_the_output_suffix(files, tmp_path):
    run("apply", files["cal"], files["session"], "-o", tmp_path / "a.npz")
    with np.load(tmp_path / "a.npz") as data:
        assert {"pose", "ax", "mx_cal"} <= set(data.files) and data["mx_cal"].dtype == float
    pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    run("apply", files["cal"], files["session"], "-o", tmp_path / "a.parquet")
    table = pq.read_table(tmp_path / "a.parquet")
    assert table.num_rows == len(files["session"].read_text().splitlines()) - 1
    # applying to a calibrated log again is refused: the _cal columns exist
    user_error("apply", files["cal"], tmp_path / "a.npz", "-o", tmp_path / "b.npz", match="_cal")


def test_parquet_without_pyarrow_is_refused_before_any_work(files, tmp_path, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "pyarrow" else real(name, *a)
    )
    line = user_error(
        "apply",
        tmp_path / "no-cal.json",
        files["session"],
        "-o",
        tmp_path / "o.parquet",
        match="pip install 'fieldcal[parquet]'",
    )
    assert "no-cal.json" not in line  # refused before the calibration file is even read


def test_export_refuses_values_no_target_can_hold(files, tmp_path):
    doc = json.loads(files["cal"].read_text())
    doc["mag"]["gain"] = [[0.0] * 3] * 3
    singular = tmp_path / "singular.json"
    singular.write_text(json.dumps(doc))
    for fmt in FORMATS:
        user_error("export", singular, "--format", fmt, match="singular")


def test_noise_command_writes_kalibr_yaml(tmp_path):
    """``fieldcal noise`` on a still recording of white noise of known σ: the yaml's densities
    are σ/√rate (within the estimate's few-percent spread) in SI units, the figure is written,
    and ``-o`` without ``--export`` is a usage error."""
    rng = np.random.default_rng(5)
    rate, n = 100.0, 60_000
    sigma_g, sigma_a = 0.5, 0.002  # deg/s and g per sample
    columns = {"t": np.arange(n) / rate}
    for axis in "xyz":
        columns[f"gyr_{axis}_dps"] = rng.normal(scale=sigma_g, size=n)
        columns[f"acc_{axis}_g"] = rng.normal(scale=sigma_a, size=n) + (axis == "z")
    path = tmp_path / "still.csv"
    np.savetxt(
        path,
        np.column_stack(list(columns.values())),
        delimiter=",",
        header=",".join(columns),
        comments="",
    )
    runner = CliRunner()
    args = ["noise", str(path), "--still", "all", "--accel-unit", "g", "--gyro-unit", "deg/s"]
    result = runner.invoke(
        cli,
        [
            *args,
            "--export",
            "kalibr",
            "-o",
            str(tmp_path / "imu.yaml"),
            "--plot",
            str(tmp_path / "allan.png"),
        ],
    )
    assert result.exit_code == 0, result.output
    values = {}
    for line in (tmp_path / "imu.yaml").read_text().splitlines():
        key, _, rest = line.partition(":")
        if rest and not line.startswith("#"):
            values[key.strip()] = float(rest.split("#")[0])
    gyro_density = np.radians(sigma_g) / np.sqrt(rate)
    accel_density = 9.80665 * sigma_a / np.sqrt(rate)
    # the largest of three axes, each within a few percent of the truth
    assert values["gyroscope_noise_density"] == pytest.approx(gyro_density, rel=0.06)
    assert values["accelerometer_noise_density"] == pytest.approx(accel_density, rel=0.06)
    assert values["update_rate"] == pytest.approx(rate)
    assert (tmp_path / "allan.png").stat().st_size > 1000
    bad = runner.invoke(cli, [*args, "-o", str(tmp_path / "x.yaml")])
    assert bad.exit_code == 2 and "--export" in bad.stderr
