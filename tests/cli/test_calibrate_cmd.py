"""``calibrate``, ``apply``, ``export`` and ``report``: the verdict first, exit code 3 on a
fail verdict (files still written), a one-line error with exit code 2 for bad input."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from _cli import lines_of, pose_csv, run, user_error

import fieldcal
from fieldcal.cli import EXIT_FAIL, cli
from fieldcal.geometry.rotations import exp_so3
from fieldcal.output.exports import FORMATS
from fieldcal.output.terminal import MAX_POSE_ROWS
from fieldcal.settings import OPTIONS, READ_OPTIONS


def test_calibrate_summary_and_json(files):
    out = files["summary"]
    doc = json.loads(files["cal"].read_text())
    # the verdict first, then each reason on its own line
    verdict = doc["verdict"]
    assert verdict["level"] == "pass"
    lines = lines_of(out)
    codes = [r["code"] for r in verdict["reasons"]]
    assert lines[0] == "verdict: PASS" + (f" ({', '.join(codes)})" if codes else "")
    assert lines[1 : 1 + len(codes)] == [f"  {r['text']}" for r in verdict["reasons"]]
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
    path = pose_csv(tmp_path / "copy.csv", session.accel, [a.copy() for a in session.accel])
    result = run("calibrate", path, "-o", tmp_path / "c.json", ok=False)
    assert result.exit_code == EXIT_FAIL == 3, (result.output, result.exception)
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["verdict"]["level"] == "fail"
    codes = [r["code"] for r in doc["verdict"]["reasons"]]
    assert codes[0] == "same_sensor"
    lines = lines_of(result.stdout)
    assert lines[0] == f"verdict: FAIL ({', '.join(dict.fromkeys(codes))})"
    assert lines[1] == f"  {doc['verdict']['reasons'][0]['text']}"
    assert lines[-1] == f"wrote {tmp_path / 'c.json'}"
    # --json: the document on stdout, the verdict on stderr, exit code 3 all the same
    result = run("calibrate", path, "--json", "-o", tmp_path / "j.json", ok=False)
    assert result.exit_code == 3 and (tmp_path / "j.json").is_file()
    assert json.loads(result.stdout)["verdict"]["level"] == "fail"
    assert lines_of(result.stderr)[0].startswith("verdict: FAIL (same_sensor")
    result = run("calibrate", path, "-q", "-o", tmp_path / "q.json", ok=False)
    assert result.exit_code == 3 and result.stdout == "" and (tmp_path / "q.json").is_file()
    assert "same_sensor" in result.stderr


def test_rejected_poses_listed_with_reasons(disturbed, tmp_path):
    out = run("calibrate", disturbed, "-o", tmp_path / "r.json").output
    doc = json.loads((tmp_path / "r.json").read_text())
    assert [(r["index"], r["sensor"]) for r in doc["rejected"]] == [(3, "mag")]
    assert doc["verdict"]["level"] == "warn"
    assert lines_of(out)[0].startswith("verdict: WARN (rejected")
    assert "rejected" in doc["poses"][3] and "rejected" not in doc["poses"][2]
    reason = doc["rejected"][0]["reason"]
    assert "rejected poses (1, left out of the fit):" in out
    assert f"  pose 3 (mag, p = {doc['rejected'][0]['p_value']:.2g}): {reason}" in out


def test_one_sensor_summary_has_no_dip(tmp_path):
    session = fieldcal.simulate("paper", seed=3)
    for name, accel, mag in (("a", session.accel, None), ("m", None, session.mag)):
        path = pose_csv(tmp_path / f"{name}.csv", accel, mag)
        out = run("calibrate", path, "-o", tmp_path / f"{name}.json").output
        doc = json.loads((tmp_path / f"{name}.json").read_text())
        assert doc["dip_deg"] is None
        assert "dip angle" not in out and "heading" not in out and "misalignment" not in out
        assert ("tilt " in out) == (accel is not None) and ("|m| " in out) == (mag is not None)


def test_long_pose_table_is_cut(tmp_path):
    n = MAX_POSE_ROWS + 5
    session = fieldcal.simulate("paper", seed=5, n_poses=n)
    path = pose_csv(tmp_path / "s.csv", session.accel, session.mag)
    out = run("calibrate", path, "-o", tmp_path / "c.json").output
    assert len(json.loads((tmp_path / "c.json").read_text())["poses"]) == n
    assert "… and 5 more poses" in out
    rows = [line.split()[0] for line in lines_of(out) if line.strip()[:2].strip().isdigit()]
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


def test_apply(files, tmp_path):
    out = tmp_path / "calibrated.csv"
    run("apply", files["cal"], files["session"], "-o", out)
    data = np.genfromtxt(out, delimiter=",", names=True)
    cal = fieldcal.Calibration.from_json(files["cal"].read_text())
    raw = np.column_stack([data["mx"], data["my"], data["mz"]])
    got = np.column_stack([data["mx_cal"], data["my_cal"], data["mz_cal"]])
    assert np.allclose(got, cal.correct_mag(raw), rtol=1e-7, atol=1e-8)
    assert np.allclose(np.linalg.norm(got, axis=1).mean(), 1.0, atol=0.02)


def _flags(command: str) -> set[str]:
    return {o for p in cli.commands[command].params for o in p.opts if o.startswith("--")}


def test_apply_and_calibrate_take_the_same_reader_flags():
    """The reader's flags come from the settings table for both commands: a new reader option
    is one settings field, on both (issue 32)."""
    reader = {f for name in READ_OPTIONS for f in OPTIONS[name].flag.split("/")}
    assert {"--accel-cols", "--current-col", "--throttle-col", "--mag"} <= reader
    assert reader <= _flags("apply") and reader <= _flags("calibrate")
    assert _flags("apply") & _flags("calibrate") >= reader


def test_apply_notes_the_reader_flags_it_does_not_need(files, tmp_path):
    plain, noted = tmp_path / "a.csv", tmp_path / "b.csv"
    run("apply", files["cal"], files["session"], "-o", plain)
    result = run(
        "apply", files["cal"], files["session"], "-o", noted, "--time-col", "t", "--mag-cols",
        "mx,my,mz",
    )  # fmt: skip
    assert "note: not used by apply: --time-col" in result.stderr
    assert plain.read_bytes() == noted.read_bytes()
    quiet = run("apply", files["cal"], files["session"], "-o", noted, "--time-col", "t", "-q",
                "--force")  # fmt: skip
    assert quiet.stderr == ""


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
    v1 = Path(__file__).parents[1] / "data" / "calibration-v0.1.json"
    assert "FIELDCAL_MAG_MATRIX" in run("export", v1, "--format", "c-header").output
    result = run("export", files["cal"], "--format", "excel", ok=False)
    assert result.exit_code == 2 and "c-header" in result.output


def test_report(files, tmp_path):
    pytest.importorskip("matplotlib", reason="matplotlib (the plot extra) not installed")
    html = tmp_path / "r.html"
    run("report", files["cal"], files["session"], "-o", html, "--png", tmp_path / "png")
    page = html.read_text()
    assert page.count("data:image/png;base64,") >= 4 and "<script" not in page
    assert {p.name for p in (tmp_path / "png").iterdir()} >= {"coverage.png", "histograms.png"}


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
    path = pose_csv(tmp_path / "s.csv", session.accel, session.mag)
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
    path = pose_csv(tmp_path / "s.csv", accel, mag)
    user_error("calibrate", path, match="tilted up and down")


def test_report_errors(files, tmp_path, monkeypatch):
    short = tmp_path / "short.csv"
    short.write_text("\n".join(files["session"].read_text().splitlines()[:100]) + "\n")
    if importlib.util.find_spec("matplotlib") is not None:  # checked after matplotlib is
        user_error(
            "report", files["cal"], short, "-o", tmp_path / "r.html", match="give the log it"
        )
    import builtins

    real_import = builtins.__import__

    def no_matplotlib(name, *args, **kwargs):
        if name.startswith("matplotlib"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    user_error("report", files["cal"], files["session"], match="fieldcal[plot]")


def test_apply_keeps_the_format_of_the_output_suffix(files, tmp_path):
    run("apply", files["cal"], files["session"], "-o", tmp_path / "a.npz")
    with np.load(tmp_path / "a.npz") as data:
        assert {"pose", "ax", "mx_cal"} <= set(data.files) and data["mx_cal"].dtype == float
    pytest.importorskip("pyarrow", reason="pyarrow (the parquet extra) not installed")
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
    for fmt, spec in FORMATS.items():
        into = ("-o", tmp_path / fmt) if spec.files is not None else ()  # a folder format
        user_error("export", singular, "--format", fmt, *into, match="singular")


@pytest.mark.parametrize("content", [b"\x00" * 10_000, b"a" * 10_000 + b"\n1\n"])
def test_apply_on_a_file_of_one_huge_name_echoes_80_characters(tmp_path, content):
    """10,000 NUL bytes read as one column name: the message shows 80 characters of it,
    escaped, not the 10 KB."""
    s = fieldcal.simulate("paper", seed=1, n_poses=10, samples=(20, 30))
    cal = tmp_path / "cal.json"
    cal.write_text(fieldcal.calibrate(s.accel, s.mag).to_json())
    log = tmp_path / "log.csv"
    log.write_bytes(content)
    line = user_error("apply", cal, log, "-o", tmp_path / "out.csv", match="no columns for")
    assert "\x00" not in line and len(line) < 80 + 200
    shown = line.split(" among ", 1)[1].split("... (1 column(s))")[0]
    assert len(shown) == 80
