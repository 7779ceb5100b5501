"""The continuous logs' rules (issue 33 item 4): the gyroscope's units, sign, scale and
alignment, the field's consistency, the turns' speed; on measured options, and end to end on
simulated logs with a known fault."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.calibration import Calibration, ParameterCovariance, SensorCalibration
from fieldcal.findings import Findings, MotionFindings
from fieldcal.methods.continuous.motion_checks import (
    gyro_check,
    gyro_units_ratio,
    turn_check,
)
from fieldcal.methods.continuous.uncertainty import NAMES
from fieldcal.simulation.handwave import simulate_handwave
from fieldcal.trust import verdict as rules


def _cols(log, prefix):
    return np.column_stack([log.columns[prefix + axis] for axis in "xyz"])


def _cov(std: float) -> ParameterCovariance:
    return ParameterCovariance(NAMES, np.eye(len(NAMES)) * std**2)


def _reasons(options, gain=None, cov=None):
    """The registered rules on a continuous fit's findings (as the estimator measures them:
    ``options`` of :func:`fit_continuous`) and its gyroscope's gain."""
    field = options.get("field_check", {})
    turns = options.get("turn_check", {})
    motion = MotionFindings(
        duration_seconds=60.0,
        field_strength_rms=field.get("strength_rms", 0.0),
        dip_spread_deg=field.get("dip_spread_deg", 0.0),
        gyro_units_ratio=options.get("gyro_units_ratio"),
        turn_step_rad=turns.get("step_rad_p99", 0.0),
        max_rate=turns.get("max_rate", 0.0),
        clipped_axes=tuple(turns.get("clipped_axes", ())),
    )
    gyro = None if gain is None else SensorCalibration(gain, np.zeros(3), 1e-6 * np.eye(3))
    cal = Calibration(
        None, None, None, None, np.zeros((0, 3, 3)), "continuous",
        covariance=cov, gyro=gyro, findings=Findings(motion=motion),
    )  # fmt: skip
    case = rules.Case(cal, None, None)
    fired = [*rules._motion(case), *rules._motion_gyro(case)]
    return [rules.reason(code, **values) for code, values in fired]


def _codes(options, gain=None, cov=None):
    return [r.code for r in _reasons(options, gain, cov)]


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
    assert _codes({}, np.eye(3), _cov(1e-3)) == []
    flip = np.diag([-1.0, -1.0, 1.0])
    assert gyro_check(flip, _cov(1e-3))["negative_axes"] == [0, 1]
    assert "gyro_gain_sign" in _codes({}, flip, _cov(1e-3))
    assert "gyro_gain_scale" in _codes({}, 1.5 * np.eye(3), _cov(1e-3))
    # a 7.6° cross-axis term on x (the phantom), determined to 0.1°
    K = np.eye(3)
    K[0, 1] = np.tan(np.radians(7.6))
    skew = gyro_check(K, _cov(np.radians(0.1)))
    assert skew["misalignment_deg"][0] == pytest.approx(7.6, abs=0.01)
    assert _codes({}, K, _cov(np.radians(0.1))) == ["gyro_misalignment"]
    # the same, undetermined by the log: a note that says so, never a misalignment
    codes = _codes({}, K, _cov(np.radians(3.0)))
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
    text = _reasons({"turn_check": clipped})[0].text
    assert "slower turns" in text and "hold" not in text
