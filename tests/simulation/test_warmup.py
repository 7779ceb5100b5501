"""Warm-up sessions (fieldcal.simulation.warmup): the drift polynomial re-expressed about another
reference is the same function, the samples are the session's plus the drift at each sample's
temperature, and the temperature follows the first-order warm-up."""

from __future__ import annotations

import numpy as np

from fieldcal.simulation.warmup import ThermalTruth, simulate_warmup


def test_the_polynomial_about_another_reference_is_the_same_drift():
    rng = np.random.default_rng(1)
    truth = ThermalTruth(20.0, {"accel": rng.normal(size=(3, 3)) * [[1e-2], [1e-3], [1e-4]]})
    t = np.linspace(15.0, 45.0, 31)
    for reference in (20.0, 31.5, 40.0):
        c = truth.about("accel", reference, order=4)
        assert c.shape == (4, 3) and np.all(c[3] == 0)
        u = (t - reference)[:, None]
        about = sum(c[k] * u ** (k + 1) for k in range(4))
        # the same function up to its value at the reference (the constant a bias absorbs)
        expected = truth.drift("accel", t) - truth.drift("accel", reference)
        np.testing.assert_allclose(about, expected, rtol=1e-10, atol=1e-13)
    np.testing.assert_array_equal(truth.drift("accel", 20.0), np.zeros(3))


def test_samples_are_the_sessions_plus_the_drift_at_their_temperature():
    w = simulate_warmup(seed=3, n_poses=6, span=20.0, start=20.0, tau=60.0)
    for i in range(6):
        drift = w.truth.drift("accel", w.temperature[i])
        np.testing.assert_allclose(w.accel[i] - drift, w.session.accel[i], atol=1e-12)
        np.testing.assert_allclose(
            w.mag[i] - w.truth.drift("mag", w.temperature[i]), w.session.mag[i], atol=1e-12
        )
    means = np.array([np.mean(t) for t in w.temperature])
    assert (
        np.all(np.diff(means) > 0) and 20.0 < means[0] < means[-1] < 40.0
    )  # warming, below T₀ + ΔT
    # first-order warm-up: T(t) = T₀ + ΔT (1 − exp(−t/τ)), sensor noise 0.02 K
    n = len(w.temperature[2])
    t = 2 * 12.0 + np.arange(n) / 100.0
    model = 20.0 + 20.0 * (1 - np.exp(-t / 60.0))
    assert np.abs(w.temperature[2] - model).max() < 5 * 0.02


def test_no_drift_gives_the_session_itself():
    w = simulate_warmup(seed=4, n_poses=3, drift={})
    for a, b in zip(w.accel, w.session.accel, strict=True):
        np.testing.assert_array_equal(a, b)
    assert w.truth.about("mag", 30.0).shape == (0, 3)
