"""Noise levels and disturbances of the continuous fit, estimated from its residuals.

- **Stretches** (``STRETCH`` seconds): each field sensor's variance per stretch, the mean of its
  squared residuals there (at least a floor). The accelerometer's residual holds its noise and
  the body's acceleration, which a hand makes in bursts: a stretch where the hand accelerates
  the device weighs by its own larger variance, rests weigh most. This is the maximum of the
  likelihood over one variance per stretch (Eq. C6 of ``docs/methods/continuous.md``).
- **Gyroscope**: one variance of the rate, ``σ_ω²``, measured from the raw rates' fourth
  differences in their quietest stretches (:func:`gyro_rate_variance`); a factor's variance is
  ``σ_ω² Δt²``. Not from the factors' residuals alone: with a rotation per epoch the trajectory
  absorbs most of them (see below).
- **What the fit keeps**: the trajectory absorbs part of every error, so variances taken from
  the residuals are divided by the share of its errors each sensor keeps
  (:func:`.uncertainty.kept_shares`, the REML-type correction); the gyroscope's rate
  variance is the raw rates' white noise unless its factors misfit far beyond it
  (:func:`.rounds.gyro_variance`).
- **Correlation in time** (body acceleration is smooth, a disturbance passes over seconds) is
  not a weight: the sandwich covariance (:mod:`.uncertainty`, Eq. C9) widens each parameter's
  error bar by what the correlated residuals do to it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["DIFFERENCE_ORDER", "STRETCH", "gyro_rate_variance", "stretch_variance"]

Array = NDArray[np.float64]

#: Seconds over which a field sensor's variance is taken as constant.
STRETCH = 2.0


def stretch_variance(residual: Array, length: int, floor: float) -> tuple[Array, Array]:
    """Per-sample variance (n,) of a sensor's residuals (n, 3), constant over stretches of
    ``length`` samples, at least ``floor``; and the stretches' own variances."""
    n = len(residual)
    k = max(1, int(length))
    m = -(-n // k)
    sq = np.zeros(m * k)
    sq[:n] = np.sum(residual**2, axis=1) / 3.0
    counts = np.minimum(k, n - np.arange(m) * k)
    per = sq.reshape(m, k).sum(axis=1) / counts
    per = np.maximum(per, floor)
    return np.repeat(per, k)[:n], per


#: The gyroscope's noise is read from differences of this order: they cancel a motion that is
#: a cubic over five samples, and a hand's turning and tremor (< 15 Hz) nearly so at 50 Hz and
#: more (second differences let through 2.2x the noise at 20 rad/s, 100 Hz; 3-12x on BROAD).
DIFFERENCE_ORDER = 4
#: Samples per stretch of the quiet-stretch estimate, and the share of the quietest stretches
#: whose boundary is read (its quantile of the stretches' variances).
QUIET_STRETCH = 128
QUIET_SHARE = 0.1
_Z_QUIET = -1.2815515655446004  # the standard normal's QUIET_SHARE quantile


def _difference_filter(order: int) -> Array:
    """The coefficients of the ``order``-th difference, ``(−1)^j C(order, j)``."""
    c = np.ones(1)
    for _ in range(order):
        c = np.convolve(c, [1.0, -1.0])
    return c


def _quiet_factor(values: int, c: Array) -> float:
    """The ``QUIET_SHARE`` quantile of a stretch's mean square of ``values`` white-noise
    differences (filter ``c``), relative to its mean: ``χ²_ν/ν`` with the degrees of freedom
    the filter's autocorrelation leaves (``ν = values / (1 + 2 Σ ρ_j²)``), by Wilson–Hilferty."""
    rho = np.correlate(c, c, "full")[len(c) :] / float(c @ c)
    nu = values / (1.0 + 2.0 * float(rho @ rho))
    a = 2.0 / (9.0 * nu)
    return float((1.0 - a + _Z_QUIET * np.sqrt(a)) ** 3)


def gyro_rate_variance(raw: Array, gain: Array) -> float:
    """``σ_ω²`` (rad²/s², per axis) of the gyroscope's white noise, robust to the motion.

    From the raw rates alone, in two steps. (1) Fourth differences
    (:data:`DIFFERENCE_ORDER`; ``Var = 70 σ²`` for white noise) cancel the smooth part of the
    motion. (2) What a hand's jitter leaves in them comes and goes, so the variance is read in
    the quietest stretches: the :data:`QUIET_SHARE` quantile of the mean squares over stretches
    of :data:`QUIET_STRETCH` samples (rests, slow turns), divided by the quantile pure white
    noise would give (:func:`_quiet_factor`), each axis in the proportion its own mean square
    has in those stretches. A log of fewer than 10 stretches takes the median absolute deviation
    of all its differences. White noise comes out unbiased (to the Gaussian approximation of
    the quantile); a rate that jitters as white noise at every sample of the log cannot be told
    from sensor noise by the rates: give ``gyro_noise`` then. The result is mapped through the
    gain: ``tr(G⁻¹ diag(σ²) G⁻ᵀ) / 3``, never below 1e-20."""
    c = _difference_filter(DIFFERENCE_ORDER)
    k = len(c) - 1
    n = len(raw) - k
    if n < 1:
        return 1e-20
    d = sum(c[j] * raw[j : j + n] for j in range(k + 1)) / np.sqrt(float(c @ c))
    d = np.asarray(d, dtype=np.float64)
    stretches = n // QUIET_STRETCH
    if stretches >= 10:
        per = np.mean(d[: stretches * QUIET_STRETCH].reshape(stretches, QUIET_STRETCH, 3) ** 2, 1)
        level = np.quantile(per.mean(axis=1), QUIET_SHARE)
        quiet = per[per.mean(axis=1) <= level]
        share = quiet.mean(axis=0) / max(float(quiet.mean()), 1e-300)
        raw_var = share * level / _quiet_factor(3 * QUIET_STRETCH, c)
    else:
        raw_var = (1.4826 * np.median(np.abs(d - np.median(d, axis=0)), axis=0)) ** 2
    Ginv = np.linalg.inv(gain)
    return float(max(np.trace(Ginv @ np.diag(raw_var) @ Ginv.T) / 3.0, 1e-20))
