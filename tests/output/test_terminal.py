"""The terminal summary (fieldcal.output.terminal): the verdict line first, user text printed
literally (never as rich markup), values rounded to their error bar's first digit, the
temperature lines."""

from __future__ import annotations

import dataclasses
import io

import numpy as np
import pytest
from _known import known_calibration
from rich.console import Console

import fieldcal
from fieldcal.calibration import Reason, Verdict
from fieldcal.output import terminal
from fieldcal.thermal import TemperatureModel


def _console() -> tuple[Console, io.StringIO]:
    out = io.StringIO()
    return Console(file=out, width=100, color_system=None, force_terminal=False), out


def test_the_verdict_and_its_reasons_are_printed_literally():
    text = "[bold]pose 3[/bold] :smile: moved"  # user words that look like markup
    cal = dataclasses.replace(
        known_calibration(), verdict=Verdict("warn", (Reason("pose_outlier", "warn", text),))
    )
    console, out = _console()
    terminal.print_verdict(console, cal)
    assert out.getvalue().splitlines() == ["verdict: WARN (pose_outlier)", f"  {text}"]
    console, out = _console()
    terminal.print_verdict(console, known_calibration())  # not judged: nothing
    assert out.getvalue() == ""


@pytest.mark.parametrize(
    ("value", "std", "text"),
    [(1.23456, 0.012, "1.23 ± 0.01"), (123.456, 3.0, "123 ± 3"), (0.5, None, "0.5"),
     (-0.00123456, 2e-5, "-0.00123 ± 2e-05"), (0.0, 0.1, "0 ± 0.1")],
)  # fmt: skip
def test_values_are_rounded_to_their_error_bar(value, std, text):
    assert terminal._pm(value, std) == text


def test_temperature_lines():
    cal = known_calibration()
    assert terminal.temperature_lines(cal.accel) == []
    model = TemperatureModel(
        25.0, np.array([[1e-3, 2e-3, -3e-3]]), np.array([18.0, 41.0]), std=np.full((1, 3), 1e-4)
    )
    lines = terminal.temperature_lines(dataclasses.replace(cal.accel, temperature=model))
    assert lines[0].startswith("  bias vs temperature: T_ref 25.0 °C, poses 18.0 to 41.0 °C")
    assert lines[1] == "    c1 = (0.001 ± 0.0001, 0.002 ± 0.0001, -0.003 ± 0.0001) raw units per K"
    refused = TemperatureModel(25.0, np.zeros((0, 3)), np.array([24.0, 26.0]), refused=True)
    (line,) = terminal.temperature_lines(dataclasses.replace(cal.accel, temperature=refused))
    assert line.endswith("span too small, no terms (calibrated at T_ref)")


def test_the_summary_starts_with_the_verdict_and_names_each_sensor():
    s = fieldcal.simulate("paper", seed=2)
    cal = fieldcal.calibrate(s.accel, s.mag)
    console, out = _console()
    terminal.print_summary(console, cal, cal.to_dict(), notes=["columns [ax] used"])
    text = out.getvalue()
    assert text.splitlines()[0] == f"verdict: {cal.verdict.summary}"
    assert "accelerometer: raw = gain · v + bias" in text and "magnetometer" in text
    assert "columns [ax] used" in text
