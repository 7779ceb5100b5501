"""Temperature terms in the static-pose likelihood: Jacobians, the order test, the span rule,
the result (cal.<sensor>.temperature, correct_*, JSON)."""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.geometry.rotations import random_rotations
from fieldcal.likelihood.levenberg import normal_equations
from fieldcal.likelihood.pose_model import State, apply_step, build_problem, residuals
from fieldcal.likelihood.temperature import MIN_SPAN_K, allowed_order
from fieldcal.simulation.warmup import simulate_warmup
from fieldcal.stats.pose_stats import summarize
from fieldcal.stats.pose_temperature import PoseTemperature, pose_temperatures
from fieldcal.thermal import TemperatureModel


@pytest.fixture(scope="module")
def warm() -> tuple[object, fieldcal.Calibration]:
    w = simulate_warmup(seed=3, n_poses=24)
    return w, fieldcal.calibrate(w.accel, w.mag, temperature=w.temperature)


def _random_state(problem, rng: np.random.Generator) -> State:  # type: ignore[no-untyped-def]
    gains = {s: np.eye(3) + 0.1 * rng.standard_normal((3, 3)) for s in problem.sensors}
    gains[problem.frame] = 0.5 * (gains[problem.frame] + gains[problem.frame].T)
    biases = {s: rng.standard_normal(3) for s in problem.sensors}
    temps = {s: 1e-3 * rng.standard_normal((problem.temp_order(s), 3)) for s in problem.temp_slice}
    return State(gains, biases, 0.7, random_rotations(problem.n, rng), temps)


def test_temperature_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(7)
    w = simulate_warmup(seed=1, n_poses=12)
    stats = summarize(w.accel, w.mag)
    means = pose_temperatures(w.temperature, 12)
    stats = stats.with_temperature(PoseTemperature(means, {"accel": 2, "mag": 1}))
    problem = build_problem(stats, "accel")
    assert problem.n_global == 22 + 3 * 3
    state = _random_state(problem, rng)
    ne = normal_equations(problem, state, residuals(problem, state))
    h = 1e-6
    for index in range(22, problem.n_global):
        dg = np.zeros(problem.n_global)
        dg[index] = h
        zero = np.zeros((problem.n, 3))
        up = residuals(problem, apply_step(problem, state, dg, zero, None))
        down = residuals(problem, apply_step(problem, state, -dg, zero, None))
        numeric = (up - down) / (2 * h)
        scale = np.abs(ne.Jg[:, :, index]).max()
        assert np.abs(numeric - ne.Jg[:, :, index]).max() <= 1e-6 * scale


def test_without_temperature_terms_the_fit_is_unchanged() -> None:
    """A constant temperature (span refused) gives the very fit made without one."""
    w = simulate_warmup(seed=4, n_poses=15, span=0.0, drift={})
    plain = fieldcal.calibrate(w.accel, w.mag)
    same = fieldcal.calibrate(w.accel, w.mag, temperature=w.temperature)
    for s in ("accel", "mag"):
        np.testing.assert_allclose(same.sensor(s).gain, plain.sensor(s).gain, rtol=0, atol=1e-12)
        np.testing.assert_allclose(same.sensor(s).bias, plain.sensor(s).bias, rtol=0, atol=1e-12)
        model = same.sensor(s).temperature
        assert model is not None and model.order == 0 and model.refused
        assert plain.sensor(s).temperature is None
    assert "temperature_span" in same.verdict.codes
    assert "temperature_span" not in plain.verdict.codes
    assert f"at least {MIN_SPAN_K:g} K" in same.options["temperature"]["refused"]


def test_warmup_terms_are_found_within_their_error_bars(warm) -> None:  # type: ignore[no-untyped-def]
    w, cal = warm
    for s in ("accel", "mag"):
        model = cal.sensor(s).temperature
        assert model.order >= 1 and model.std is not None
        truth = w.truth.about(s, model.reference, model.order)[: model.order]
        z = (model.coefficients - truth) / model.std
        assert np.abs(z).max() < 4.5  # seeded: 4.5σ is a false alarm of 1e-4 per number
        lo, hi = w.truth.start, w.truth.start + 20.0
        assert lo - 1 < model.span[0] < model.span[1] < hi + 1


def test_correct_with_temperature_removes_the_drift(warm) -> None:  # type: ignore[no-untyped-def]
    """Corrected pose means have |a| = 1 (unit fields) when the bias follows the temperature; a
    bias held constant leaves the drift in them."""
    w, cal = warm
    plain = fieldcal.calibrate(w.accel, w.mag)

    def norm_error(c: fieldcal.Calibration, use_t: bool) -> float:
        out = []
        for raw, temp in zip(w.accel, w.temperature, strict=True):
            body = c.correct_accel(raw, temperature=temp if use_t else None).mean(axis=0)
            out.append(np.linalg.norm(body) - 1.0)
        return float(np.sqrt(np.mean(np.square(out))))

    assert norm_error(cal, True) < 0.8 * norm_error(plain, False)
    # without the temperature the same calibration corrects at the reference temperature only
    assert norm_error(cal, True) < norm_error(cal, False)


def test_json_round_trip_keeps_the_model(warm) -> None:  # type: ignore[no-untyped-def]
    _, cal = warm
    again = fieldcal.Calibration.from_json(cal.to_json())
    assert again == cal
    for s in ("accel", "mag"):
        a, b = cal.sensor(s).temperature, again.sensor(s).temperature
        np.testing.assert_array_equal(a.coefficients, b.coefficients)
        np.testing.assert_allclose(a.std, b.std, rtol=1e-12)


def test_no_temperature_effect_selects_no_term() -> None:
    w = simulate_warmup(seed=11, n_poses=24, drift={})
    cal = fieldcal.calibrate(w.accel, w.mag, temperature=w.temperature)
    assert cal.options["temperature"]["orders"] == {}
    assert all(cal.sensor(s).temperature.order == 0 for s in ("accel", "mag"))


def test_span_rule() -> None:
    t = PoseTemperature(np.linspace(20.0, 20.0 + 2 * MIN_SPAN_K + 0.1, 12))
    assert allowed_order(t) == 2
    assert allowed_order(PoseTemperature(np.array([20.0, 20.0, 40.0, 40.0]))) == 0


def test_shift_is_clipped_to_the_span() -> None:
    model = TemperatureModel(30.0, [[1.0, 0.0, 0.0], [0.1, 0.0, 0.0]], [25.0, 35.0])
    np.testing.assert_allclose(model.shift(40.0), model.shift(35.0))
    np.testing.assert_allclose(model.shift(31.0)[0], 1.0 + 0.1)


def test_bad_temperature_is_one_line() -> None:
    w = simulate_warmup(seed=2, n_poses=12)
    with pytest.raises(ValueError, match="one array of temperatures per pose"):
        fieldcal.calibrate(w.accel, w.mag, temperature=w.temperature[:-1])
    bad = [t + 1000.0 for t in w.temperature]
    with pytest.raises(ValueError, match="°C"):
        fieldcal.calibrate(w.accel, w.mag, temperature=bad)
