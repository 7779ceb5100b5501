"""The magnetometer's interference term on simulated flights with a known truth
(:mod:`fieldcal.simulation.multirotor`, independent of the estimator), its verdict rules, and
its way through the command line and the JSON."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from fieldcal.interference import InterferenceModel
from fieldcal.simulation.multirotor import simulate_flight
from fieldcal.trust.interference_fit import (
    FAIL_SHARE,
    WARN_SHARE,
    fit_interference,
    interference_reasons,
    quaternion_rotations,
)


def _fit(flight, **options):
    return fit_interference(
        flight.mag,
        quaternion_rotations(flight.attitude),
        {"current": flight.current},
        start_gain=flight.gain,
        start_bias=flight.bias,
        **options,
    )


def _true_heading_error(flight, d):
    """The worst heading error (degrees) a body-frame disturbance d (µT, raw) causes on a
    level vehicle, computed from the truth: its horizontal part in field units."""
    delta = np.linalg.solve(flight.gain, d)
    horizontal = math.hypot(flight.field[0], flight.field[1])
    return math.degrees(math.asin(min(1.0, math.hypot(delta[0], delta[1]) / horizontal)))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_flight_interference_recovered(seed):
    """≥ 90 % of the current-correlated variation removed; within 4 standard errors; at full
    current the heading error left ≤ 2° where uncorrected ≥ 10°."""
    flight = simulate_flight(seed, seconds=120.0, interference_ut=25.0)
    model = _fit(flight)
    assert model.identifiable and model.inputs == ("current",)
    c = model.coefficients[0]
    u = flight.current - flight.current.mean()
    true_part = u[:, None] * flight.coefficients
    left = u[:, None] * (flight.coefficients - c)
    removed = 1.0 - np.sum(left**2) / np.sum(true_part**2)
    assert removed >= 0.90, removed
    assert np.all(np.abs(c - flight.coefficients) < 4 * model.std[0])
    assert np.all(model.crb[0] <= model.std[0] * 1.5)  # the bound is below the sandwich
    peak = flight.current.max()
    uncorrected = _true_heading_error(flight, flight.coefficients * peak)
    corrected = _true_heading_error(flight, (flight.coefficients - c) * peak)
    assert uncorrected >= 10.0 and corrected <= 2.0, (uncorrected, corrected)
    assert abs(model.heading_error_deg - uncorrected) < 0.2 * uncorrected + 1.0
    share = np.linalg.norm(flight.coefficients) * peak / np.linalg.norm(flight.field)
    assert model.field_share == pytest.approx(share, rel=0.1)


def test_constant_current_is_not_identifiable():
    flight = simulate_flight(7, seconds=60.0, current_varies=False)
    model = _fit(flight)
    assert not model.identifiable
    assert "add a throttle sweep" in model.reason
    assert np.all(model.coefficients == 0)
    codes = [code for code, _ in interference_reasons(model)]
    assert codes == ["interference_not_identifiable"]


def _model(share):
    return InterferenceModel(
        ("current",),
        ("A",),
        [[1.0, 0, 0]],
        [10.0],
        [[0.01] * 3],
        [[0.001] * 3],
        [[2, 40]],
        field_share=share,
        heading_error_deg=20.0,
        heading_error_corrected_deg=1.0,
    )


def test_verdict_thresholds_are_ardupilots():
    assert interference_reasons(_model(WARN_SHARE - 0.01)) == []
    assert [c for c, _ in interference_reasons(_model(0.45))] == ["interference"]
    assert [c for c, _ in interference_reasons(_model(FAIL_SHARE + 0.01))] == [
        "interference_unusable"
    ]
    model = _model(0.45)
    assert model.shift({"current": np.array([10.0, 20.0])})[1] == pytest.approx([10.0, 0, 0])
    assert model.at_zero() == pytest.approx([10.0, 0, 0])


def test_flight_csv_through_the_command_line(tmp_path):
    """A flight log with current and the autopilot's attitude: the JSON carries the term, the
    verdict its reason; apply-free correction with Calibration.correct_mag removes it."""
    from click.testing import CliRunner

    from fieldcal.calibration import Calibration
    from fieldcal.cli import cli

    flight = simulate_flight(5, seconds=60.0, interference_ut=30.0)
    path = _write_csv(tmp_path / "flight.csv", flight.columns())
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(
        cli, ["calibrate", str(path), "--sensors", "mag", "--poses", "samples", "-o", str(out)]
    )
    assert out.is_file(), result.output
    doc = json.loads(out.read_text())
    cal = Calibration.from_json(out.read_text())
    model = cal.mag.interference
    assert model is not None and model.identifiable
    assert np.all(np.abs(model.coefficients[0] - flight.coefficients) < 4 * model.std[0])
    codes = [r["code"] for r in (doc.get("calibration", doc))["verdict"]["reasons"]]
    assert "interference" in codes or "interference_unusable" in codes
    assert Calibration.from_json(cal.to_json()) == cal


def test_apply_takes_the_term_off_with_each_rows_current(tmp_path):
    """apply on a log with the current column: the corrected field has the constant norm of
    the calibrated field with the term removed; without the column, a one-line error."""
    from fieldcal.calibration import Calibration
    from fieldcal.logs.apply import apply_to_file

    flight = simulate_flight(11, seconds=60.0, interference_ut=30.0, attitude_error_deg=0.0)
    model = _fit(flight)
    gain = flight.gain
    bias = flight.bias + flight.coefficients * flight.current.mean()  # holds at the mean
    sensor = _sensor(gain, bias, model)
    cal = Calibration(None, sensor, None, np.array([1.0, 0.0, 0.0]), np.zeros((0, 3, 3)), "x")
    path = _write_csv(tmp_path / "f.csv", flight.columns(), ["mx", "my", "mz", "current"])
    out = tmp_path / "out.csv"
    apply_to_file(cal, path, out)
    data = np.genfromtxt(out, delimiter=",", names=True)
    fixed = np.column_stack([data["mx_cal"], data["my_cal"], data["mz_cal"]])
    norm = np.linalg.norm(fixed, axis=1)
    assert norm.std() < 0.01 * norm.mean()  # the 30 µT of interference are gone
    plain = np.linalg.norm(np.linalg.solve(gain, (flight.mag - bias).T).T, axis=1)
    assert plain.std() > 5 * norm.std()
    bare = _write_csv(tmp_path / "bare.csv", flight.columns(), ["mx", "my", "mz"])
    with pytest.raises(Exception, match="no current column; name it with --current-col"):
        apply_to_file(cal, bare, tmp_path / "o2.csv")


def _sensor(gain, bias, model):
    from fieldcal.calibration import SensorCalibration

    return SensorCalibration(gain, bias, 0.09 * np.eye(3), interference=model)


def _write_csv(path, cols, names=None):
    """A flight's columns (``names``: those, default all) as a CSV log with a header."""
    names = list(cols) if names is None else names
    table = np.column_stack([cols[k] for k in names])
    np.savetxt(path, table, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
    return path
