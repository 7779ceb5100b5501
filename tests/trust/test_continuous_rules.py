"""The continuous logs' rules (issue 33 item 4): the gyroscope's units, sign, scale and
alignment, the field's consistency, the turns' speed; on measured options, and end to end on
simulated logs with a known fault."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.calibration import ParameterCovariance
from fieldcal.methods.continuous.motion_checks import (
    gyro_check,
    gyro_units_ratio,
    turn_check,
)
from fieldcal.methods.continuous.uncertainty import NAMES
from fieldcal.simulation.handwave import simulate_handwave
from fieldcal.trust.continuous_motion import motion_reasons


def _cols(log, prefix):
    return np.column_stack([log.columns[prefix + axis] for axis in "xyz"])


def _cov(std: float) -> ParameterCovariance:
    return ParameterCovariance(NAMES, np.eye(len(NAMES)) * std**2)


def _codes(options):
    return [r.code for r in motion_reasons(options)]


def test_gyroscope_in_degrees_is_caught_before_any_fit():
    log = simulate_handwave(seed=4, seconds=20.0)
    t, m, g = log.columns["t"], _cols(log, "m"), _cols(log, "g")
    ratio = gyro_units_ratio(t, m, g)
    assert ratio is not None and 0.5 < ratio < 1.5
    wrong = gyro_units_ratio(t, m, np.degrees(g))
    assert wrong is not None and 57.3 * 0.5 < wrong < 57.3 * 1.5
    assert _codes({"gyro_units_ratio": wrong}) == ["gyro_units"]
    assert _codes({"gyro_units_ratio": ratio}) == []


def test_gyroscope_sign_scale_and_misalignment():
    good = gyro_check(np.eye(3), _cov(1e-3))
    assert _codes({"gyro_check": good}) == []
    flipped = gyro_check(np.diag([-1.0, -1.0, 1.0]), _cov(1e-3))
    assert flipped["negative_axes"] == [0, 1]
    assert "gyro_gain_sign" in _codes({"gyro_check": flipped})
    scaled = gyro_check(1.5 * np.eye(3), _cov(1e-3))
    assert "gyro_gain_scale" in _codes({"gyro_check": scaled})
    # a 7.6° cross-axis term on x (the phantom), determined to 0.1°
    K = np.eye(3)
    K[0, 1] = np.tan(np.radians(7.6))
    skew = gyro_check(K, _cov(np.radians(0.1)))
    assert skew["misalignment_deg"][0] == pytest.approx(7.6, abs=0.01)
    assert _codes({"gyro_check": skew}) == ["gyro_misalignment"]
    # the same, undetermined by the log: a note that says so, never a misalignment
    loose = gyro_check(K, _cov(np.radians(3.0)))
    codes = _codes({"gyro_check": loose})
    assert "gyro_misalignment" not in codes and "gyro_undetermined" in codes


def test_field_and_turn_rules():
    field = {"strength_rms": 0.15, "strength_worst_stretch": 0.4, "dip_spread_deg": 5.4}
    assert _codes({"field_check": field}) == ["continuous_field_disturbed"]
    field["strength_rms"] = 0.03
    assert _codes({"field_check": field}) == []
    t = np.arange(500) / 100.0
    slow = turn_check(t, np.full((499, 3), 1.0), np.sin(t)[:, None] * np.ones(3))
    assert _codes({"turn_check": slow}) == []
    fast = turn_check(t, np.full((499, 3), 20.0), np.sin(t)[:, None] * np.ones(3))
    assert _codes({"turn_check": fast}) == ["continuous_fast_turns"]
    raw = np.clip(30 * np.sin(t), -20, 20)[:, None] * np.ones(3)
    clipped = turn_check(t, np.full((499, 3), 1.0), raw)
    assert clipped["clipped_axes"] == [0, 1, 2]
    text = motion_reasons({"turn_check": clipped})[0].text
    assert "slower turns" in text and "hold" not in text
