"""Repeat a pose when warmer (:mod:`fieldcal.planning.warmer_poses`): said when the poses'
temperature span limits the temperature terms, with the temperature to reach; not otherwise.
Shown by ``fieldcal plan`` and in the capture view."""

from __future__ import annotations

import dataclasses

import pytest
from click.testing import CliRunner

import fieldcal
from fieldcal.capture.view import temperature_lines
from fieldcal.cli import cli
from fieldcal.planning.warmer_poses import temperature_advice, temperature_span_line
from fieldcal.simulation.warmup import simulate_warmup


@pytest.fixture(scope="module")
def base():
    return fieldcal.simulate("paper", seed=1).truth


def _with(cal, record, gyro=None):
    options = {**cal.options, "temperature": record}
    if gyro is not None:
        options["gyro"] = {"temperature": gyro}
    return dataclasses.replace(cal, options=options)


def test_a_span_under_5_k_asks_for_a_warmer_pose(base):
    cal = _with(base, {"span_c": [21.0, 24.2], "allowed_order": 0, "orders": {}})
    advice = temperature_advice(cal)
    assert advice.startswith("repeat a pose when the board is warmer")
    assert "3.2 K" in advice and "26.0 °C or above" in advice
    assert "need 5 K" in temperature_span_line(cal.options["temperature"])


def test_an_order_at_the_spans_limit_asks_for_the_next_orders_span(base):
    record = {"span_c": [20.0, 28.0], "allowed_order": 1, "orders": {"accel": 1}}
    advice = temperature_advice(_with(base, record))
    assert "accel took order 1" in advice and "order 2 needs 10 K" in advice
    assert "30.0 °C or above" in advice
    # the gyroscope's order counts too
    gyro = temperature_advice(_with(base, {**record, "orders": {}}, gyro={"order": 1}))
    assert gyro is not None and "gyro took order 1" in gyro


@pytest.mark.parametrize(
    "record",
    [
        {"span_c": [20.0, 28.0], "allowed_order": 1, "orders": {}},  # no effect: enough
        {"span_c": [20.0, 40.0], "allowed_order": 3, "orders": {"mag": 3}},  # cubic: the most
        {"span_c": [20.0, 40.0], "allowed_order": 3, "orders": {}, "note": "method"},
    ],
    ids=["no-effect", "cubic", "no-terms-method"],
)
def test_no_advice_when_the_span_does_not_limit(base, record):
    assert temperature_advice(_with(base, record)) is None


def test_without_a_temperature_column_nothing_is_said(base):
    assert temperature_advice(base) is None
    assert temperature_lines(base) == []


def test_plan_and_the_capture_view_say_it_for_a_short_warmup(tmp_path):
    w = simulate_warmup(seed=5, n_poses=14, span=3.0)
    cal = fieldcal.calibrate(w.accel, w.mag, temperature=w.temperature)
    lines = temperature_lines(cal)
    assert lines[0].startswith("temperature: poses at") and "need 5 K" in lines[0]
    assert lines[1].startswith("repeat a pose when the board is warmer")
    path = tmp_path / "cal.json"
    path.write_text(cal.to_json())
    result = CliRunner().invoke(cli, ["plan", str(path)])
    assert result.exit_code == 0, result.output
    assert "repeat a pose when the board is warmer" in result.output
    as_json = CliRunner().invoke(cli, ["plan", str(path), "--json"])
    assert "repeat a pose" not in as_json.output  # the JSON stays the list of poses
