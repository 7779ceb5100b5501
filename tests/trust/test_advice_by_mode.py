"""Advice from the mode (issue 34, item 7): a continuous fit's accuracy reasons ask for more
motion, never still poses; the "auto" note of a continuous fit gives no still-pose advice;
``plan`` on a continuous calibration names the turns to add in command-line terms."""

from __future__ import annotations

import pytest
from _cli import user_error

import fieldcal
from fieldcal.simulation.continuous import simulate_continuous


@pytest.fixture(scope="module")
def few_rests(tmp_path_factory):
    """Five rests joined by motion: too few poses, so poses='auto' takes the motion."""
    path = tmp_path_factory.mktemp("few") / "few.csv"
    simulate_continuous("paper", seed=3, n_poses=5).write_csv(str(path))
    run = fieldcal.calibrate_log(str(path), targets=fieldcal.Targets(tilt_deg=0.01))
    return path, run


def test_a_continuous_fits_accuracy_reason_asks_for_motion(few_rests):
    _, cal = few_rests
    assert "trajectory" in cal.options
    texts = [r.text for r in cal.verdict.reasons if r.code in ("accuracy", "unusable")]
    assert texts, cal.verdict.summary
    assert all("record the motion longer" in t and "still" not in t for t in texts)


def test_a_static_fits_accuracy_reason_still_asks_for_poses():
    s = fieldcal.simulate("paper", seed=2)
    cal = fieldcal.calibrate(s.accel, s.mag, targets=fieldcal.Targets(tilt_deg=0.001))
    texts = [r.text for r in cal.verdict.reasons if r.code in ("accuracy", "unusable")]
    assert texts and all("record more poses, still" in t for t in texts)


def test_the_auto_note_of_a_continuous_fit_gives_no_still_pose_advice(few_rests):
    path, _ = few_rests
    from fieldcal.pipeline import read_log, run_log

    run = run_log(read_log(str(path)))
    (note,) = [n for n in run.notes if n.startswith("poses='auto'")]
    assert "continuous motion" in note and "5 pose(s) found" in note
    assert "hold the device still" not in note and "further orientations" not in note


def test_plan_on_a_continuous_calibration_names_the_turns(few_rests, tmp_path):
    _, cal = few_rests
    path = tmp_path / "cal.json"
    path.write_text(cal.to_json())
    line = user_error("plan", path, match="from continuous motion")
    assert "--poses continuous" in line and "samples=" not in line
    assert "turn it" in line
