"""Noise levels of the continuous fit (fieldcal.methods.continuous.weights): per-stretch
variances as known answers (a partial last stretch, the floor), and the gyroscope's white-noise
variance recovered through the motion: a smooth one, a hand's fast turns and a tremor that comes
and goes, where second differences were biased (issue 33 item 5)."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.methods.continuous.weights import gyro_rate_variance, stretch_variance
from fieldcal.simulation.handheld import simulate_handheld


def _second_difference_variance(raw):
    """The estimate before issue 33: the MAD of the second differences, over 6."""
    d2 = raw[2:] - 2.0 * raw[1:-1] + raw[:-2]
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    return float(np.mean((1.4826 * mad) ** 2 / 6.0))


def test_stretch_variances_are_the_mean_squares_per_stretch():
    residual = np.zeros((7, 3))
    residual[:3] = 2.0  # stretch 0: mean square per axis 4
    residual[3:6] = [[3.0, 0.0, 0.0]] * 3  # stretch 1: (9 + 0 + 0) / 3 = 3
    residual[6] = 0.0  # a partial last stretch of one sample: the floor
    per_sample, per = stretch_variance(residual, length=3, floor=0.5)
    np.testing.assert_array_equal(per, [4.0, 3.0, 0.5])
    np.testing.assert_array_equal(per_sample, [4, 4, 4, 3, 3, 3, 0.5])
    _, one = stretch_variance(residual, length=0, floor=0.0)  # a length under 1: one sample
    np.testing.assert_array_equal(one, [4, 4, 4, 3, 3, 3, 0])


@pytest.mark.parametrize("sigma", [1e-3, 5e-3])
def test_the_gyroscopes_white_noise_is_found_through_the_motion(sigma):
    rng = np.random.default_rng(7)
    n, rate = 20_000, 100.0
    t = np.arange(n) / rate
    motion = np.column_stack([np.sin(0.5 * t), 0.3 * np.cos(0.2 * t), 0.1 * t])  # smooth, large
    gain = np.diag([1.02, 0.97, 1.0])
    raw = motion @ gain.T + sigma * rng.standard_normal((n, 3))
    found = gyro_rate_variance(raw, gain)
    expected = sigma**2 * np.mean(1 / np.diag(gain) ** 2)
    # the 10 % quietest of 156 stretches of 128 fourth differences: a few percent
    assert found == pytest.approx(expected, rel=0.08)
    assert gyro_rate_variance(np.zeros((10, 3)), gain) == 1e-20  # never zero


@pytest.mark.parametrize(("seed", "rate", "rests"), [(0, 100.0, 0), (1, 50.0, 0), (2, 100.0, 3)])
def test_fast_hand_turns_do_not_bias_the_gyroscopes_noise(seed, rate, rests):
    """The hand-held test bed's 20 rad/s turns (0.1-1.5 Hz): second differences take the
    turning for noise (2.2x the std at 100 Hz, 13x at 50 Hz); the estimate is within 10 %."""
    log = simulate_handheld(seed, seconds=40.0, rate=rate, max_rate=20.0, rests=rests)
    raw = np.column_stack([log.columns[k] for k in ("gx", "gy", "gz")])
    truth = float(np.trace(log.truth.gyro.noise_cov)) / 3.0
    gain = np.eye(3)  # the raw rates' own noise: the truth is per raw axis
    assert np.sqrt(gyro_rate_variance(raw, gain) / truth) == pytest.approx(1.0, abs=0.1)
    assert np.sqrt(_second_difference_variance(raw) / truth) > 1.25


def test_a_tremor_that_comes_and_goes_is_not_taken_for_noise():
    """A 9-12 Hz tremor of 0.2 rad/s half the time, rests between: the quiet stretches carry
    the white noise alone; the second differences (and the fourth, over the whole log) do not."""
    rng = np.random.default_rng(3)
    n, rate, sigma = 30_000, 200.0, 2e-3
    t = np.arange(n) / rate
    on = (np.floor(t / 5.0) % 2 == 0).astype(float)  # 5 s on, 5 s off
    freq = rng.uniform(9.0, 12.0, 3)
    phase = rng.uniform(0, 2 * np.pi, 3)
    tremor = 0.2 * on[:, None] * np.sin(2 * np.pi * freq * t[:, None] + phase)
    raw = tremor + sigma * rng.standard_normal((n, 3))
    found = np.sqrt(gyro_rate_variance(raw, np.eye(3)))
    assert found == pytest.approx(sigma, rel=0.1)
    assert np.sqrt(_second_difference_variance(raw)) > 1.5 * sigma
