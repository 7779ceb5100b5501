"""A log's temperature column: recognised, carried into each pose, fitted by calibrate_log."""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.logs.columns import recognise_columns
from fieldcal.logs.log import load_log
from fieldcal.simulation.warmup import simulate_warmup_log


@pytest.mark.parametrize(
    ("names", "expected"),
    [
        (["t", "ax", "ay", "az", "temp"], ("temp", "t")),
        (["time", "ax", "ay", "az", "t_degc"], ("t_degc", "time")),
        (["ax", "ay", "az", "IMU Temp (C)", "timestamp"], ("IMU Temp (C)", "timestamp")),
        (["ax", "ay", "az", "temperature"], ("temperature", None)),
    ],
)
def test_temperature_columns_are_recognised(names: list[str], expected: tuple) -> None:
    found = recognise_columns(names)
    assert found["temperature"] == [expected[0]]
    assert found.get("time", [None]) == [expected[1]]


def test_a_warmup_log_is_calibrated_with_temperature_terms(tmp_path) -> None:  # type: ignore[no-untyped-def]
    w = simulate_warmup_log(seed=2, n_poses=18, span=20.0)
    path = tmp_path / "warm.csv"
    w.write_csv(str(path))
    log = load_log(path)
    assert log.temperature is not None and log.used["temperature"] == ["temp"]
    cal = fieldcal.calibrate_log(path)
    assert cal.n_poses == 18
    orders = cal.options["temperature"]["orders"]
    assert orders, "a 20 K warm-up with drifting biases selects temperature terms"
    for s in orders:
        model = cal.sensor(s).temperature
        lo, hi = model.span
        assert 15.0 < hi - lo <= 20.5
    # the same log with the column named explicitly, and without it: no terms
    renamed = tmp_path / "renamed.csv"
    text = path.read_text().replace(",temp\n", ",board_heat\n", 1)
    renamed.write_text(text)
    plain = fieldcal.calibrate_log(renamed)
    assert "temperature" not in plain.options and plain.accel.temperature is None
    named = fieldcal.calibrate_log(renamed, temp_col="board_heat")
    assert named.options["temperature"]["orders"] == orders


def test_a_broken_temperature_column_is_left_out_with_a_note(tmp_path) -> None:  # type: ignore[no-untyped-def]
    w = simulate_warmup_log(seed=2, n_poses=10, span=20.0)
    w.columns["temp"][5] = np.nan
    path = tmp_path / "warm.csv"
    w.write_csv(str(path))
    log = load_log(path)
    assert log.temperature is None
    assert any("temperature column 'temp'" in note for note in log.notes)
