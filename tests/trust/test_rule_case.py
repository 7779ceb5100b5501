"""What a rule reads (Case) and the owner registry a check declares its codes in."""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.trust import verdict
from fieldcal.trust.rule_case import OWNER, Case, owns


def test_a_check_cannot_own_a_code_twice_or_an_unknown_code():
    with pytest.raises(KeyError, match="owned by"):
        owns("accuracy")(lambda case: iter(()))
    with pytest.raises(KeyError, match="not in RULES"):
        owns("no_such_code")(lambda case: iter(()))


def test_the_verdict_module_exports_the_same_registry():
    assert verdict.OWNER is OWNER and verdict.Case is Case
    assert OWNER["accuracy"] == "_accuracy"


def test_a_case_of_poses_reads_the_field_directions_per_pose():
    s = fieldcal.simulate("paper", seed=3)
    cal = fieldcal.calibrate(s.accel, s.mag)
    stats = fieldcal.stats.pose_stats.summarize(s.accel, s.mag)
    case = Case(cal, stats, None)
    assert case.sensors == ("accel", "mag")
    u = case.body_directions("accel")
    assert u.shape == (len(s.accel), 3)
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0, rtol=1e-12)
    alone = Case(fieldcal.calibrate(s.accel, None), None, None)
    assert alone.sensors == ("accel",)
