"""A PoseSet: each pose's mean as numpy's mean gives it, the record written to the JSON, a
window cut's motion."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.logs.pose_set import MOTION_PERCENTILE, PoseSet, WindowCut


def test_means_are_numpys_and_computed_once():
    rng = np.random.default_rng(2)
    accel = [rng.normal(size=(n, 3)) * 1e3 for n in (1, 5, 40)]
    poses = PoseSet(accel, None, [{"samples": len(a)} for a in accel], None, 100.0)
    np.testing.assert_allclose(poses.means("accel"), [a.mean(axis=0) for a in accel], rtol=1e-15)
    assert poses.means("accel") is poses.means("accel")
    with pytest.raises(ValueError, match="no mag poses"):
        poses.means("mag")
    with pytest.raises(ValueError, match="'accel' or 'mag'"):
        poses.means("gyro")
    assert poses.n == 3 and not poses.time_ordered


def test_the_record_says_how_the_poses_were_made():
    cut = WindowCut(25, 0.25, 40, "accel", drift=0.01, spread=0.02, limit=0.05, turn=0.001)
    assert cut.motion == 0.02
    poses = PoseSet(None, None, [{"samples": 25}] * 40, None, 100.0, "windows", cut)
    record = poses.record()
    assert record["source"] == "windows" and record["rate_hz"] == 100.0
    assert record["percentile"] == MOTION_PERCENTILE and record["window_s"] == 0.25
    assert record["turn_deg_s"] == pytest.approx(np.degrees(0.001) * 100)
    samples = PoseSet(None, None, [{"samples": 3}, {"samples": 1}], None, None, "samples")
    assert samples.record()["samples_per_pose"] == 3 and samples.time_ordered
