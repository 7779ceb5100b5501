"""Predicted accuracy with temperature terms: the terms' uncertainty over the logged span is
part of it (issue 34, item 1), so a warm-up calibration predicts errors the size it makes and
is judged against the targets like any other. The 200-session study is in
benchmarks/temperature.py; here a dozen sessions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import fieldcal
from fieldcal.simulation.measured import measured_accuracy
from fieldcal.simulation.warmup import simulate_warmup
from fieldcal.trust.accuracy import predict_accuracy, temperature_span

KEYS = ("tilt_deg", "heading_deg", "accel_norm_rel", "mag_norm_rel")


@pytest.fixture(scope="module")
def warmups():
    out = []
    for seed in range(12):
        w = simulate_warmup(seed=seed)
        cal = fieldcal.calibrate(w.accel, w.mag, temperature=w.temperature)
        out.append((w, cal))
    return out


def test_predicted_errors_match_the_measured_ones_over_the_span(warmups):
    predicted, measured = [], []
    for w, cal in warmups:
        assert cal.accel.temperature.order > 0 and cal.mag.temperature.order > 0
        span = temperature_span(cal)
        got = measured_accuracy(cal, w.session.truth, span, w.truth.drift)
        predicted.append([getattr(cal.accuracy, k) for k in KEYS])
        measured.append([got[k] for k in KEYS])
    ratio = np.sqrt(np.mean(np.square(predicted), 0) / np.mean(np.square(measured), 0))
    assert np.all((ratio > 0.5) & (ratio < 2.0)), dict(zip(KEYS, ratio, strict=True))


def test_the_span_is_the_logged_one_and_the_terms_count(warmups):
    w, cal = warmups[0]
    low, high = temperature_span(cal)
    temps = np.concatenate(w.temperature)
    assert low == pytest.approx(temps.min(), abs=0.5) and high == pytest.approx(
        temps.max(), abs=0.5
    )
    # at the reference temperature alone the terms add nothing: the span's prediction is larger
    narrow = cal.accel.temperature
    point = dataclasses.replace(
        cal,
        accel=dataclasses.replace(
            cal.accel,
            temperature=dataclasses.replace(narrow, span=np.array([narrow.reference] * 2)),
        ),
        mag=dataclasses.replace(
            cal.mag,
            temperature=dataclasses.replace(
                cal.mag.temperature, span=np.array([cal.mag.temperature.reference] * 2)
            ),
        ),
    )
    assert predict_accuracy(point).tilt_deg < cal.accuracy.tilt_deg


def test_a_sensor_with_temperature_terms_is_judged_against_the_targets(warmups):
    w, _ = warmups[1]
    tight = fieldcal.calibrate(
        w.accel, w.mag, temperature=w.temperature, targets=fieldcal.Targets(tilt_deg=1e-3)
    )
    assert tight.verdict.level != "pass"
    assert "accuracy" in [r.code for r in tight.verdict.reasons] or "unusable" in [
        r.code for r in tight.verdict.reasons
    ]
