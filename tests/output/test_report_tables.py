"""The report's HTML parts: numbers rounded at their error bar, user text shown literally, the
poses listed with their rows, the tables of a calibration."""

from __future__ import annotations

import dataclasses

import pytest

import fieldcal
from fieldcal.output.report_tables import (
    correction_html,
    esc,
    plain,
    pm,
    poses_of,
    rejected_html,
    uncertainty_html,
)


def test_a_value_is_rounded_where_its_error_bar_second_digit_falls():
    assert pm(1.234567, 0.0123) == "1.235 ± 0.012"
    assert pm(123.456, 25.0) == "123 ± 25"
    assert pm(0.5) == "0.5" and pm(0.5, 0.0) == "0.5" and pm(None) == "n/a"
    assert pm(float("nan"), 0.1) == "n/a"


def test_user_text_is_shown_literally():
    assert esc('<b>"x"&') == "&lt;b&gt;&quot;x&quot;&amp;"
    assert plain("cost $5") == r"cost \$5"


@pytest.fixture(scope="module")
def cal():
    s = fieldcal.simulate("paper", seed=8)
    return fieldcal.calibrate(s.accel, s.mag)


def test_the_poses_without_a_log_have_no_rows(cal):
    poses = poses_of(cal, None)
    assert [p.position for p in poses] == list(range(len(cal.poses)))
    assert all(p.rows.size == 0 and p.rejected is None for p in poses)
    assert all(p.residual["accel"].shape == (3,) for p in poses)


def test_the_tables_hold_the_numbers_of_the_calibration(cal):
    correction = correction_html(cal)
    assert "accelerometer" in correction and "magnetometer" in correction
    assert f"{cal.accel.bias[0]:.4g}"[:4] in correction
    assert "<table" in uncertainty_html(cal)
    assert rejected_html(cal, poses_of(cal, None)) == "<p>No pose was rejected.</p>"
    row = dict(cal.poses[0], rejected="mag: <far> off")
    marked = dataclasses.replace(cal, poses=(row, *cal.poses[1:]))
    assert "&lt;far&gt;" in rejected_html(marked, poses_of(marked, None))
