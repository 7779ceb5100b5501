"""Eq. C6a–C6b (``methods/continuous/motion_noise.py``): body acceleration counted once per
stretch beyond chance, and the field direction's allowance."""

from __future__ import annotations

import numpy as np

from fieldcal.methods.continuous.motion_noise import (
    CHANCE,
    FIELD_DIRECTION_DEG,
    field_direction_variance,
    once_per_stretch,
    sample_excess,
)
from fieldcal.methods.continuous.weights import stretch_variance


def _variances(residual: np.ndarray, k: int) -> np.ndarray:
    return stretch_variance(residual, k, 0.0)[0]


def test_white_noise_keeps_its_weight():
    """Stretches of white noise alone scatter by √(2/(3k)) of their variance; that chance is not
    body acceleration: (nearly) every sample keeps its variance."""
    rng = np.random.default_rng(3)
    k, sigma = 200, 0.02
    v = _variances(sigma * rng.standard_normal((400 * k, 3)), k)
    out = once_per_stretch(v, k)
    white = np.quantile(v, 0.1)
    # beyond the quietest tenth by more than CHANCE scatters: about 1 stretch in 1000 (a
    # variance's scatter is slightly skewed), at most 1 %
    assert np.mean(out > white * 1.001) < 0.01
    assert np.all(out >= white - 1e-15)
    assert np.median(out) / sigma**2 < 1.0 + 3.0 * np.sqrt(2.0 / (3.0 * k))


def test_body_acceleration_counts_once_per_stretch():
    """A stretch whose residual holds one acceleration ``c`` shared by its k samples (the
    hand's, correlated over the stretch) weighs as one observation of it: its per-sample
    variance is k times the excess, so the stretch's information about a shared offset,
    k / v, is that of one sample of variance |c|²/3 (within the chance term)."""
    rng = np.random.default_rng(5)
    k, sigma = 100, 0.01
    residual = sigma * rng.standard_normal((50 * k, 3))
    c = np.array([0.05, -0.03, 0.04])
    residual[7 * k : 8 * k] += c
    out = once_per_stretch(_variances(residual, k), k)
    white = np.quantile(out, 0.1)
    excess = np.sum(c**2) / 3.0
    chance = CHANCE * white * np.sqrt(2.0 / (3.0 * k))
    information = k / out[7 * k]
    assert abs(information - 1.0 / excess) < 0.1 / excess
    quiet = np.delete(out, np.arange(7 * k, 8 * k))
    assert np.max(quiet) < white * 1.001 + k * chance  # the others: chance at most


def test_field_direction_allowance():
    """(2/3)(σ_f |m − b|)²: a direction error of σ_f moves the field by σ_f |m| across the two
    axes perpendicular to it; independent of the bias's place, quadratic in the strength."""
    rng = np.random.default_rng(7)
    bias = np.array([10.0, -5.0, 3.0])
    u = rng.standard_normal((20, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    strength = rng.uniform(20.0, 60.0, 20)
    extra = field_direction_variance(bias + strength[:, None] * u, bias)
    # the mean square displacement of a vector of length s turned by a small random angle of
    # RMS σ_f about the axes perpendicular to it, per axis: s² σ_f² · 2/3
    sigma = np.radians(FIELD_DIRECTION_DEG)
    assert np.allclose(extra, (2.0 / 3.0) * (sigma * strength) ** 2, rtol=1e-12)
    turns = rng.standard_normal((20000, 3)) * sigma / np.sqrt(2.0)
    v = np.array([0.0, 0.0, 1.0])
    moved = v + np.cross(turns, v)  # first order; the turn about v itself moves nothing
    per_axis = np.mean(np.sum((moved - v) ** 2, axis=1)) / 3.0
    assert abs(per_axis - (2.0 / 3.0) * sigma**2 / 2.0 * 1.0) < 0.05 * per_axis


def test_the_excess_is_read_from_the_samples():
    """C6a at the knots (:func:`sample_excess`): a stretch whose samples carry a fast
    acceleration (alternating ±c, which a knot's window mean of an even number of samples
    cancels) has the excess |c|²/3 read from the samples, whole; the white stretches none."""
    rng = np.random.default_rng(11)
    k, sigma, step = 120, 0.01, 6
    sq_noise = np.sum((sigma * rng.standard_normal((40 * k, 3))) ** 2, axis=1) / 3.0
    residual = sigma * rng.standard_normal((40 * k, 3))
    c = np.array([0.05, -0.03, 0.04])
    residual[5 * k : 6 * k] += np.where(np.arange(k) % 2 == 0, 1.0, -1.0)[:, None] * c
    excess = sample_excess(np.sum(residual**2, axis=1) / 3.0, k)
    assert len(excess) == 40
    assert abs(excess[5] - np.sum(c**2) / 3.0) < 0.1 * np.sum(c**2) / 3.0
    assert np.count_nonzero(np.delete(excess, 5)) <= 1  # the others: chance at most
    # the knots' own means do not see it: their stretch's variance stays near the white one's
    means = residual.reshape(-1, step, 3).mean(axis=1)
    per_knot = np.mean(np.sum(means**2, axis=1).reshape(40, k // step), axis=1) / 3.0
    assert per_knot[5] < 3.0 * np.median(per_knot)
    assert np.all(sample_excess(sq_noise, k) < 3.0 * CHANCE * sigma**2 * np.sqrt(2.0 / (3 * k)))
