"""Pose tests (fieldcal.trust.outliers): the joint deletion identity is made only where a pose
has few degrees of freedom of its own, and then once per test."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

import fieldcal
from fieldcal.trust import fitting, outliers

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from _small_sets import shots


def _count_calls(monkeypatch) -> dict[str, int]:
    """Spy on the pose tests and on the joint identity's eigen-decompositions."""
    counts = {"tests": 0, "joint": 0}
    tests, joint = outliers.pose_tests, outliers._joint_deletion

    def counted_tests(*args):
        counts["tests"] += 1
        return tests(*args)

    def counted_joint(*args):
        counts["joint"] += 1
        return joint(*args)

    monkeypatch.setattr(fitting, "pose_tests", counted_tests)
    monkeypatch.setattr(outliers, "_joint_deletion", counted_joint)
    return counts


def test_many_poses_need_no_joint_deletion(monkeypatch):
    # 40 poses leave each sensor far more than MIN_OWN_DOF degrees of freedom per pose
    counts = _count_calls(monkeypatch)
    s = fieldcal.simulate("paper", seed=0, n_poses=40)
    fieldcal.calibrate(s.accel, s.mag)
    assert counts["tests"] >= 1 and counts["joint"] == 0


def test_few_poses_make_the_joint_deletion_once_per_test(monkeypatch):
    counts = _count_calls(monkeypatch)
    accel, mag = shots(12, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # small-set notes are not what is tested
        cal = fieldcal.calibrate(accel, mag)
    assert counts["joint"] == counts["tests"] >= 1
    assert np.isfinite(cal.cost)
