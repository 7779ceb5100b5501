"""Too few poses found: the message names the settings that find more, with how many, and each
count is what those settings really give; the retries are bounded and reuse the loaded log."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
from _cli import user_error
from _logs import _csv

import fieldcal
from fieldcal import pipeline
from fieldcal.errors import InputError
from fieldcal.logs import load_log, pose_hints, poses_from_log
from fieldcal.logs.pose_hints import MAX_RETRIES
from fieldcal.logs.pose_hints import pose_hints as hints_of
from fieldcal.methods import enough_poses

HINT = re.compile(
    r"with ((?:--[a-z-]+ [^ :;]+ ?)+)(?: \(if recorded at [0-9.]+ Hz\))?: (\d+) poses"
)


def _rests(seed, n_poses=14, rest=30, move=30):
    """A log without time: ``n_poses`` rests of ``rest`` samples (shorter than the default
    --min-still of 50 samples), ``move`` samples of violent motion between them."""
    s = fieldcal.simulate("paper", seed=seed, n_poses=n_poses, samples=(rest, rest))
    rng = np.random.default_rng(seed)
    acc, mag, label = [], [], []
    for i in range(n_poses):
        acc.append(s.accel[i])
        mag.append(s.mag[i])
        label.append(np.full(rest, float(i)))
        if i + 1 == n_poses:
            break
        u = np.linspace(0.0, 1.0, move)[:, None]
        for out, x in ((acc, s.accel), (mag, s.mag)):
            a, b = x[i].mean(0), x[i + 1].mean(0)
            span = np.linalg.norm(b - a) + np.linalg.norm(a)
            out.append(a + u * (b - a) + 0.2 * span * rng.standard_normal((move, 3)))
        label.append(np.full(move, np.nan))
    a, m = np.concatenate(acc), np.concatenate(mag)
    columns = {f"a{c}": a[:, j] for j, c in enumerate("xyz")}
    columns.update({f"m{c}": m[:, j] for j, c in enumerate("xyz")})
    return columns, np.concatenate(label)


def _options(flags: str) -> dict[str, float | str]:
    """``"--window 6 --min-still 12"`` as poses_from_log's keywords."""
    words = flags.split()
    names = {"--still-threshold": "threshold", "--pose-col": "pose_col"}
    out: dict[str, float | str] = {}
    for flag, value in zip(words[0::2], words[1::2], strict=True):
        key = names.get(flag, flag[2:].replace("-", "_"))
        out[key] = value if key in ("pose_col", "poses") else float(value)
    return out


def _check_claims(message: str, path, least: int) -> list[tuple[str, int]]:
    """Every "with FLAGS: N poses" of ``message`` is what FLAGS give on ``path``."""
    claims = [(flags.strip(), int(n)) for flags, n in HINT.findall(message)]
    assert claims, message
    for flags, n in claims:
        options = _options(flags)
        pose_col = options.pop("pose_col", None)
        log = load_log(path, pose_col=pose_col)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the detector's own (rests that move)
            assert poses_from_log(log, **options).n == n, (flags, message)
    assert max(n for _, n in claims) >= least, message
    return claims


def test_short_rests_without_time_name_the_settings_that_find_them(tmp_path):
    columns, _ = _rests(5)
    path = _csv(tmp_path / "rests.csv", columns)
    line = user_error("calibrate", path, "-o", tmp_path / "c.json", match="other settings find")
    claims = _check_claims(line, path, least=14)
    assert any(flags.startswith("--rate") for flags, _ in claims), line
    assert "no time column" in line and "or hold the device still" in line
    # the advice is taken: the fit goes through
    best = next(flags for flags, n in claims if n == 14 and not flags.startswith("--rate"))
    cal = fieldcal.calibrate_log(path, **_options(best))
    assert len(cal.poses) == 14


def test_a_pose_like_column_is_named_with_its_count(tmp_path):
    columns, label = _rests(6)
    columns["position"] = label  # not recognised as a pose column by its name
    path = _csv(tmp_path / "labelled.csv", columns)
    assert load_log(path).pose is None
    line = user_error("calibrate", path, "-o", tmp_path / "c.json", match="--pose-col position")
    claims = _check_claims(line, path, least=14)
    assert claims[0] == ("--pose-col position", 14)  # a labelling column comes first


def test_no_rest_at_all_still_names_the_settings(tmp_path):
    columns, label = _rests(7)
    columns["shot"] = label
    path = _csv(tmp_path / "rests.csv", columns)
    line = user_error(
        "calibrate", path, "--poses", "still", "--min-still", 400, "-o", tmp_path / "c.json",
        match="no still interval of at least 400 samples",
    )  # fmt: skip
    assert "--pose-col shot: 14 poses" in line
    _check_claims(line, path, least=14)


def test_session3_without_rate(shared_data, tmp_path):
    path = shared_data("icm20948-deadtomgc") / "derived" / "session3.csv"
    line = user_error("calibrate", path, "-o", tmp_path / "c.json", match="1 pose(s) found")
    claims = _check_claims(line, path, least=9)
    assert any(flags.startswith("--rate") for flags, _ in claims)  # no time column
    assert len(line) < 400


def test_sap6_shots_name_the_shot_column_and_the_devices(shared_data, tmp_path):
    path = shared_data("sap6") / "derived" / "sap6_shots.csv"
    line = user_error("calibrate", path, "-o", tmp_path / "c.json", match="--pose-col shot: 24")
    assert "7 devices (column 'device'" in line and "give each device its own log" in line
    assert len(line) < 400


def test_the_retries_are_bounded_and_reuse_the_log(tmp_path, monkeypatch):
    columns, label = _rests(8)
    columns["shot"] = label
    columns["orientation"] = label
    log = load_log(_csv(tmp_path / "rests.csv", columns))
    calls = []
    real = pose_hints.poses_from_log

    def counted(*args, **kwargs):
        calls.append(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(pose_hints, "poses_from_log", counted)
    found = hints_of(log)
    # the detections, plus one grouping per labelling column, plus windows/samples at most
    assert 0 < len(calls) <= MAX_RETRIES + 2 + 1
    assert [h.flags for h in found[:2]] == ["--pose-col shot", "--pose-col orientation"]
    # a long log gets fewer: RETRY_SAMPLES in all
    calls.clear()
    monkeypatch.setattr(pose_hints, "RETRY_SAMPLES", 3 * log.n)
    hints_of(log)
    detections = [c for c in calls if "window" in c]  # not the groupings by a column
    assert len(detections) <= 3


def test_no_advice_for_poses_given(tmp_path, monkeypatch):
    """capture passes the poses it found: the message stays cheap (no retries)."""

    def refuse(*args, **kwargs):
        raise AssertionError("no retries for poses given")

    monkeypatch.setattr(pipeline, "pose_advice", refuse)
    monkeypatch.setattr(enough_poses, "pose_advice", refuse)  # the pose check's
    columns, label = _rests(9, n_poses=5)
    columns["pose"] = label
    log = load_log(_csv(tmp_path / "five.csv", columns))
    poses = poses_from_log(log)
    assert poses.n == 5
    with pytest.raises(InputError, match="further orientations"):
        pipeline.run_log(log, found=poses)
