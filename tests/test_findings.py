"""Typed findings (fieldcal.findings) travel with the calibration: each estimator fills in
its kind, the file carries them under ``findings`` and reading it back gives them again, so a
report or a plan made from the file judges what the fit saw."""

from __future__ import annotations

import json

import numpy as np
import pytest

import fieldcal
from fieldcal.findings import Findings, GyroFindings, MotionFindings, PoseCorrelation
from fieldcal.simulation.continuous import simulate_continuous
from fieldcal.simulation.handwave import simulate_handwave


@pytest.fixture(scope="module")
def with_gyro():
    return fieldcal.calibrate_log(simulate_continuous("paper", seed=3).columns, gravity=9.80665)


def test_the_gyroscope_stage_reports_its_segments(with_gyro):
    found = with_gyro.findings.gyro
    assert isinstance(found, GyroFindings)
    assert found.segments_used == len(with_gyro.gyro_segments) > 0
    assert 0.0 <= found.p_value <= 1.0 and found.widening >= 1.0
    assert with_gyro.findings.motion is None  # a pose calibration


def test_findings_are_written_and_read_back(with_gyro):
    doc = json.loads(with_gyro.to_json())
    assert doc["findings"]["gyro"]["segments_used"] == with_gyro.findings.gyro.segments_used
    again = fieldcal.Calibration.from_json(with_gyro.to_json())
    assert again.findings == with_gyro.findings


def test_a_file_without_findings_loads_with_none():
    s = fieldcal.simulate("paper", seed=1)
    doc = json.loads(fieldcal.calibrate(s.accel, s.mag).to_json())
    doc.pop("findings", None)
    assert fieldcal.Calibration.from_json(json.dumps(doc)).findings == Findings()


def test_correlated_poses_and_continuous_motion_fill_their_kinds():
    log = simulate_handwave(seed=2, seconds=30.0)
    cal = fieldcal.calibrate_log(log.columns, poses="continuous")
    assert isinstance(cal.findings.motion, MotionFindings) and cal.findings.gyro is None
    slow = simulate_handwave(seed=2, seconds=60.0, turn_rate=0.05, shake=0.0, rate=20.0)
    no_gyro = {k: v for k, v in slow.columns.items() if not k.startswith("g")}
    windows = fieldcal.calibrate_log(no_gyro, poses="samples")
    found = windows.findings.pose_correlation
    assert isinstance(found, PoseCorrelation) and found.poses > 10
    record = windows.options["pose_correlation"]  # the documented key stays
    assert np.isclose(record["tau"], found.tau) and "correlated_poses" in windows.verdict.codes
