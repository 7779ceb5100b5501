"""Temperature terms where people read them: the terminal summary (coefficients with error
bars, or why none) and the report's figure of bias against temperature (the poses' biases and
the fitted curve, which passes through them)."""

from __future__ import annotations

import io

import numpy as np
import pytest
from rich.console import Console

import fieldcal
from fieldcal.output.report import _temperature_series, report_figures
from fieldcal.output.terminal import print_summary, temperature_lines
from fieldcal.simulation.warmup import simulate_warmup, simulate_warmup_log


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    w = simulate_warmup_log(seed=2, n_poses=18, span=20.0)
    path = tmp_path_factory.mktemp("warm") / "warm.csv"
    w.write_csv(str(path))
    return path, fieldcal.calibrate_log(path)


def test_the_summary_gives_each_order_with_its_error_bars(warm):
    _, cal = warm
    console = Console(file=io.StringIO(), width=120, record=True)
    print_summary(console, cal, {}, [])
    text = console.export_text()
    for s in ("accel", "mag", "gyro"):
        model = cal.sensor(s).temperature
        lines = temperature_lines(cal.sensor(s))
        assert lines[0] in text and f"T_ref {model.reference:.1f} °C" in lines[0]
        assert len(lines) == 1 + model.order and "±" in lines[1]


def test_the_summary_says_why_there_are_no_terms():
    w = simulate_warmup(seed=4, n_poses=15, span=0.0, drift={})
    cal = fieldcal.calibrate(w.accel, w.mag, temperature=w.temperature)
    assert temperature_lines(cal.accel)[0].endswith(
        "span too small, no terms (calibrated at T_ref)"
    )
    plain = fieldcal.calibrate(w.accel, w.mag)
    assert temperature_lines(plain.accel) == []


def test_the_report_draws_the_poses_biases_on_the_fitted_curve(warm):
    path, cal = warm
    series = _temperature_series(cal)
    assert set(series) == {"accel", "mag", "gyro"}
    for s in ("accel", "mag"):
        model, t, bias = series[s]
        curve = np.asarray(cal.sensor(s).bias) + model.shift(t)
        # the poses scatter about the curve by their pose-level and sample noise only
        spread = np.abs(bias - curve).max()
        drift = np.abs(model.shift(t)).max()
        assert spread < 0.2 * drift
    pytest.importorskip("matplotlib", reason="matplotlib (the plot extra) not installed")
    figures = report_figures(cal)  # without the log: the calibration holds the data
    assert "temperature" in figures
    assert len(figures["temperature"].axes) == 3
    with_log = report_figures(cal, path)
    assert "temperature" in with_log
