"""A device's calibrations over time (fieldcal.output.drift): the table's rows as known answers
from a store of three calibrations (one moved bias), the common temperature as the median of the
references, the figure's panels."""

from __future__ import annotations

import dataclasses
import io

import numpy as np
import pytest
from rich.console import Console

import fieldcal
from fieldcal.output import drift
from fieldcal.thermal import TemperatureModel


@pytest.fixture(scope="module")
def cal():
    s = fieldcal.simulate("paper", seed=8)
    return fieldcal.calibrate(s.accel, s.mag)


def _rows(cal, tmp_path, temperatures=None):
    store = fieldcal.Store(tmp_path)
    moved = cal.accel.bias + np.array([20 * cal.accel.bias_std[0], 0.0, 0.0])
    versions = [
        cal,
        cal,
        dataclasses.replace(cal, accel=dataclasses.replace(cal.accel, bias=moved)),
    ]
    for month, version in enumerate(versions, start=1):
        if temperatures is not None:
            model = TemperatureModel(
                temperatures[month - 1], np.zeros((1, 3)), np.array([0.0, 60.0])
            )
            version = dataclasses.replace(
                version, accel=dataclasses.replace(version.accel, temperature=model)
            )
        store.add(dataclasses.replace(version, created=f"2026-0{month}-01T00:00:00Z"), device="d7")
    return store.drift("d7")


def test_the_table_names_what_moved(cal, tmp_path):
    rows = _rows(cal, tmp_path)
    out = io.StringIO()
    Console(file=out, width=140, color_system=None).print(drift.drift_table(rows))
    lines = [" ".join(line.split()) for line in out.getvalue().splitlines()]
    assert lines[0].strip() == "d7: 3 calibrations"
    body = [line for line in lines if line.startswith("2026-")]
    assert len(body) == 3
    assert body[0].endswith("(first)") and body[1].endswith("nothing")
    assert body[2].endswith("accel.bias[0] (+14.1)")  # 20 σ over √2 combined
    assert all(f"{cal.dip_deg:.2f}" in line for line in body)


def test_biases_are_compared_at_the_median_reference(cal, tmp_path):
    rows = _rows(cal, tmp_path, temperatures=[20.0, 35.0, 26.0])
    assert drift.common_temperatures(rows) == {"accel": 26.0}
    assert drift.common_temperatures(_rows(cal, tmp_path / "plain")) == {}


def test_the_figure_has_a_panel_per_group_present(cal, tmp_path):
    pytest.importorskip("matplotlib", reason="matplotlib (the plot extra) not installed")
    fig = drift.drift_figure(_rows(cal, tmp_path))
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == [
        "accelerometer scale",
        "accelerometer bias",
        "magnetometer scale",
        "magnetometer bias",
        "dip (°)",
    ]
    # the moved bias is ringed in red on the third calibration
    ringed = [line for line in fig.axes[1].lines if line.get_markeredgecolor() == "red"]
    assert len(ringed) == 1 and len(ringed[0].get_xdata()) == 1
