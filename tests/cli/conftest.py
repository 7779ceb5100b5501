"""The CLI tests' shared logs: a simulated session calibrated once, and one with a disturbed
pose."""

from __future__ import annotations

import numpy as np
import pytest
from _cli import pose_csv, run

import fieldcal


@pytest.fixture(scope="module")
def disturbed(tmp_path_factory):
    """20 poses whose pose 3 has a magnetometer offset of 30 % of the field (iron nearby)."""
    session = fieldcal.simulate("paper", seed=4, n_poses=20)
    mag = [m.copy() for m in session.mag]
    mag[3] += np.array([0.3, 0.0, 0.0]) * np.abs(mag[3]).max()
    return pose_csv(tmp_path_factory.mktemp("disturbed") / "s.csv", session.accel, mag)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli")
    session = folder / "session.csv"
    run("simulate", "--seed", 4, "-o", session, "--truth", folder / "truth.json")
    cal = folder / "cal.json"
    result = run("calibrate", session, "-o", cal, "--gravity", 9.80665)
    return {"folder": folder, "session": session, "cal": cal, "summary": result.output}
