"""Two calibrations side by side (:mod:`fieldcal.comparison`): temperature apart from ageing.

A device calibrated twice, once warmer: its biases differ by the temperature terms alone. The
comparison (and the store's drift view) evaluates both at a common temperature, so a warmer
session is no change and an aged bias still is."""

from __future__ import annotations

import dataclasses
import importlib.util
from math import comb

import numpy as np
import pytest
from click.testing import CliRunner

import fieldcal
from fieldcal.cli import cli
from fieldcal.comparison import common_temperature, compare
from fieldcal.simulation.warmup import simulate_warmup
from fieldcal.thermal import TemperatureModel

#: The drift plot needs matplotlib (the plot extra); without it the table is still checked.
PLOT = importlib.util.find_spec("matplotlib") is not None


@pytest.fixture(scope="module")
def cal():
    w = simulate_warmup(seed=3, n_poses=24)
    fitted = fieldcal.calibrate(w.accel, w.mag, temperature=w.temperature)
    assert fitted.accel.temperature.order >= 1
    return fitted


def _rereferenced(cal, delta):
    """The same device described about ``T_ref + delta`` (the bias there, the polynomial
    re-expanded): what a session centred ``delta`` K warmer estimates, noise aside."""
    changes = {}
    for s in ("accel", "mag"):
        sensor = cal.sensor(s)
        model = sensor.temperature
        c = model.coefficients
        K = model.order
        new = np.zeros_like(c)
        for k in range(1, K + 1):  # u = v + δ: c'_k = Σ_{j≥k} C(j, k) δ^(j−k) c_j
            new[k - 1] = sum(comb(j, k) * delta ** (j - k) * c[j - 1] for j in range(k, K + 1))
        assert model.reference + delta <= model.span[1]  # inside: the model holds there
        shift = model.shift(model.reference + delta)
        moved = TemperatureModel(model.reference + delta, new, model.span)
        changes[s] = dataclasses.replace(sensor, bias=sensor.bias + shift, temperature=moved)
    return dataclasses.replace(cal, **changes)


def test_a_warmer_session_is_no_change_at_a_common_temperature(cal):
    warmer = _rereferenced(cal, 4.0)
    # the stored biases differ far beyond their errors: they hold 4 K apart
    raw = np.abs(warmer.accel.bias - cal.accel.bias) / cal.accel.bias_std
    assert raw.max() > 10
    result = compare(cal, warmer)
    assert result.changed == ()
    low, high = cal.accel.temperature.span
    assert result.temperature["accel"] == pytest.approx(0.5 * (low + high))
    biases = [c for c in result.changes if c.name.startswith("accel.bias")]
    assert all(abs(c.difference) < 1e-12 * (abs(c.before) + 1) for c in biases)
    # the coefficients are compared too (the temperature behaviour), and the first-order ones
    # moved by the re-expansion of the quadratic term about another reference
    names = {c.name for c in result.changes}
    assert "accel.temp[1,0]" in names and "mag.temp[2,2]" in names


def test_an_aged_bias_is_still_flagged(cal):
    aged_bias = cal.accel.bias + np.array([0.0, 10 * cal.accel.bias_std[1], 0.0])
    aged = dataclasses.replace(cal, accel=dataclasses.replace(cal.accel, bias=aged_bias))
    warmer_and_aged = _rereferenced(aged, 4.0)
    assert [c.name for c in compare(cal, warmer_and_aged).changed] == ["accel.bias[1]"]


def test_common_temperature_is_where_a_calibration_without_terms_holds(cal):
    flat = TemperatureModel(25.0, np.zeros((0, 3)), np.array([24.0, 26.0]), refused=True)
    other = dataclasses.replace(cal, accel=dataclasses.replace(cal.accel, temperature=flat))
    assert common_temperature(cal, other, "accel") == 25.0
    plain = dataclasses.replace(cal, accel=dataclasses.replace(cal.accel, temperature=None))
    assert common_temperature(cal, plain, "accel") is None


def test_store_drift_says_the_common_temperature(cal, tmp_path):
    store = fieldcal.Store(tmp_path)
    store.add(dataclasses.replace(cal, created="2026-01-01T00:00:00Z"), device="d1")
    warmer = _rereferenced(cal, 4.0)
    store.add(dataclasses.replace(warmer, created="2026-02-01T00:00:00Z"), device="d1")
    rows = store.drift("d1")
    assert rows[1].since_previous.changed == ()
    plot = ["--plot", str(tmp_path / "d.png")] if PLOT else []  # the plot needs matplotlib
    result = CliRunner().invoke(cli, ["store", "drift", "d1", "--store", str(tmp_path), *plot])
    assert result.exit_code == 0, result.output
    assert "nothing (biases compared at accel" in " ".join(result.output.split())
    assert not PLOT or (tmp_path / "d.png").stat().st_size > 1000
