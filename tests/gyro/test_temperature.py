"""The gyroscope's bias against temperature from the still poses' means
(:mod:`fieldcal.gyro.temperature`): the coefficients within their error bars, the order
chosen by the data within the span rule, refused under 5 K, and on a warm-up log through
:func:`fieldcal.calibrate_log` (``cal.gyro.temperature``, ``cal.correct_gyro(raw,
temperature=...)``)."""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.gyro.temperature import fit_bias_temperature
from fieldcal.likelihood.temperature import MIN_SPAN_K
from fieldcal.simulation.warmup import simulate_warmup_log


def _poses(rng, n, span, coefficients, sigma=1e-3):
    """Pose means of a bias ``b + Σ c_k (T − 30)^k`` plus white noise of ``sigma``."""
    T = np.sort(30.0 - span / 2 + span * rng.random(n))
    d = T - 30.0
    b = np.array([0.01, -0.02, 0.005])
    truth = b + sum(np.outer(d ** (k + 1), c) for k, c in enumerate(coefficients))
    means = truth + sigma * rng.standard_normal((n, 3))
    cov = np.broadcast_to(sigma**2 * np.eye(3), (n, 3, 3)).copy()
    return means, cov, T, b


def test_coefficients_are_found_within_their_error_bars():
    rng = np.random.default_rng(11)
    c = [np.array([2e-3, -1e-3, 5e-4]), np.array([4e-5, 2e-5, -3e-5])]
    means, cov, T, b = _poses(rng, 24, 20.0, c)
    fit = fit_bias_temperature(means, cov, T, reference=30.0)
    assert fit.model.order == 2 and not fit.model.refused
    std = np.sqrt(np.diag(fit.covariance))
    estimate = np.concatenate([fit.bias, fit.model.coefficients.ravel()])
    z = (estimate - np.concatenate([b, *c])) / std
    assert np.abs(z).max() < 4.5  # seeded: 4.5σ is a false alarm of 1e-4 per number
    assert fit.record["tests"][-1]["kept"] is False or fit.record["allowed_order"] == 2


def test_no_temperature_effect_selects_no_term_in_most_sessions():
    """The F-test at 1 %: on 200 seeded sessions without drift, a term is selected in about
    1 % (binomial: 8 or more of 200 has probability below 1e-3)."""
    selected = 0
    for seed in range(200):
        rng = np.random.default_rng(seed)
        means, cov, T, _ = _poses(rng, 18, 20.0, [])
        fit = fit_bias_temperature(means, cov, T)
        selected += fit.model.order > 0
        if fit.model.order == 0:
            assert fit.bias is None and fit.covariance is None
    assert selected <= 8


def test_a_span_under_the_rule_is_refused_with_the_span_needed():
    rng = np.random.default_rng(3)
    means, cov, T, _ = _poses(rng, 18, 3.0, [np.array([5e-3, 5e-3, 5e-3])])
    fit = fit_bias_temperature(means, cov, T)
    assert fit.model.refused and fit.model.order == 0 and fit.bias is None
    assert f"at least {MIN_SPAN_K:g} K" in fit.record["refused"]


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    w = simulate_warmup_log(seed=2, n_poses=18, span=20.0)
    path = tmp_path_factory.mktemp("warm") / "warm.csv"
    w.write_csv(str(path))
    return w, fieldcal.calibrate_log(path)


def test_a_warmup_log_gives_the_gyroscope_its_temperature_terms(warm):
    w, cal = warm
    model = cal.gyro.temperature
    assert model is not None and model.order >= 1 and model.std is not None
    # one reference for all sensors, and the terms within their error bars
    assert model.reference == pytest.approx(cal.accel.temperature.reference)
    truth = w.truth.about("gyro", model.reference, model.order)[: model.order]
    assert np.abs((model.coefficients - truth) / model.std).max() < 4.5
    record = cal.options["gyro"]["temperature"]
    assert record["order"] == model.order and record["tests"][0]["kept"]
    names = cal.covariance.names
    assert "gyro.temp[1,0]" in names and "gyro.bias[0]" in names


def test_correct_gyro_uses_the_bias_at_the_temperature(warm):
    _, cal = warm
    g = cal.gyro
    T = np.array([22.0, 30.0, 38.0])
    raw = np.asarray(g.bias) + g.temperature.shift(T)  # the gyroscope at rest
    rest = cal.correct_gyro(raw, temperature=T)
    assert np.abs(rest).max() < 1e-12
    # without the temperature, the drift reads as a rate: the terms matter
    assert np.abs(cal.correct_gyro(raw)).max() > 1e-3
