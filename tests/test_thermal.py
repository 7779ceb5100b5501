"""A bias against temperature (fieldcal.thermal): Horner's evaluation against the polynomial
written out, clipping to the span seen, scaling, and the checks."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.thermal import TemperatureModel, temperature_names


def _model() -> TemperatureModel:
    c = np.array([[1e-2, -2e-2, 3e-3], [1e-4, 0.0, -5e-5], [2e-6, 1e-6, 0.0]])
    return TemperatureModel(25.0, c, np.array([5.0, 45.0]))


def test_shift_is_the_cubic_written_out_and_clipped_to_the_span():
    m = _model()
    t = np.array([[5.0, 12.5], [25.0, 45.0]])
    d = t - 25.0
    c = m.coefficients
    expected = d[..., None] * c[0] + d[..., None] ** 2 * c[1] + d[..., None] ** 3 * c[2]
    np.testing.assert_allclose(m.shift(t), expected, rtol=1e-13, atol=1e-16)
    assert np.array_equal(m.shift(25.0), np.zeros(3))
    np.testing.assert_array_equal(m.shift(-40.0), m.shift(5.0))  # no extrapolation
    np.testing.assert_array_equal(m.shift(100.0), m.shift(45.0))
    assert (m.order, m.width) == (3, 40.0)


def test_scaled_model_for_scaled_readings():
    m = _model()
    std = np.full((3, 3), 1e-5)
    m = TemperatureModel(m.reference, m.coefficients, m.span, std=std)
    s = m.scaled(-4.0)
    np.testing.assert_allclose(s.shift(33.0), -4.0 * m.shift(33.0), rtol=1e-14)
    np.testing.assert_array_equal(s.std, 4.0 * std)


def test_no_terms_is_order_zero_and_a_zero_shift():
    m = TemperatureModel(20.0, np.zeros((0, 3)), np.array([20.0, 20.0]))
    assert m.order == 0 and np.array_equal(m.shift([10.0, 30.0]), np.zeros((2, 3)))


def test_bad_models_and_temperatures_are_refused():
    with pytest.raises(ValueError, match="span must be"):
        TemperatureModel(25.0, np.zeros((1, 3)), np.array([40.0, 10.0]))
    with pytest.raises(ValueError, match="must be finite"):
        TemperatureModel(np.nan, np.zeros((1, 3)), np.array([10.0, 40.0]))
    with pytest.raises(ValueError, match="temperatures must be finite"):
        _model().shift([20.0, np.inf])


def test_names_follow_the_coefficients_ravel_order():
    assert temperature_names(2) == [f"temp[{k},{j}]" for k in (1, 2) for j in range(3)]
    assert temperature_names(0) == []
